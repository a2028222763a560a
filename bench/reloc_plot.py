#!/usr/bin/python3
"""The unaligned position error of replays of one TUM folder against its ground truth, frame by
frame, lost frames marked (docs/tracking.md, "Candidates from colour"; docs/reloc_xyzrpy.png).

    reloc_plot.py GROUNDTRUTH OUT.png LABEL=RUN [LABEL=RUN ...]

RUN: a `bitfuse replay` output folder (trajectory.txt, frames.csv). The ground truth is
interpolated at each frame's depth time (positions linearly).
"""
import csv
import sys

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np


def errors(gt, run):
    e = np.loadtxt(run + '/trajectory.txt')
    g = np.stack([np.interp(e[:, 0], gt[:, 0], gt[:, k]) for k in (1, 2, 3)], 1)
    states = [r['state'] for r in csv.DictReader(open(run + '/frames.csv'))]
    return np.linalg.norm(e[:, 1:4] - g, axis=1) * 1e3, np.array(states)


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    gt = np.loadtxt(sys.argv[1])
    fig, ax = plt.subplots(figsize=(9, 3.6))
    for spec in sys.argv[3:]:
        label, run = spec.split('=', 1)
        err, states = errors(gt, run)
        k = np.arange(len(err))
        line, = ax.plot(k, err, label=label, lw=1.2)
        lost = states == 'lost'
        ax.plot(k[lost], err[lost], 'x', ms=3, color=line.get_color())
        for i in np.flatnonzero(states == 'relocalised'):
            ax.axvline(i, color=line.get_color(), lw=0.6, ls=':')
    ax.set_xlabel('frame (x: lost, reported at the last pose kept; dotted: relocalised)')
    ax.set_ylabel('unaligned position error [mm]')
    ax.set_yscale('log')
    ax.set_ylim(1, 1000)  # the first frame is at the true pose: 0
    ax.grid(True, which='both', lw=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=110)


if __name__ == '__main__':
    main()
