"""Shared by the bench scripts' Python (bench/*.sh run it from the source
root, with `sys.path.insert(0, "bench")`): a run's outputs, and the
Markdown table and plot each script writes into docs/."""
import csv
import json


def run_outputs(run):
    """A replay's or fuse's stats.json and its eval-surface --json, as dicts."""
    with open(run + "/stats.json") as f:
        stats = json.load(f)
    with open(run + "/surface.json") as f:
        surface = json.load(f)
    return stats, surface


def stage_ms(stats, name):
    """The median GPU time of a stage [ms], rounded, or "" when the run has none."""
    g = stats["gpu_stage_ms"]
    return round(g[name]["median"], 1) if name in g else ""


def read_rows(tsv):
    """The rows of a tab-separated table with a header line, as dicts."""
    with open(tsv) as f:
        return list(csv.DictReader(f, delimiter="\t"))


def write_table(path, title, intro, rows):
    """docs/NAME.md: a title, a paragraph, and the rows as a Markdown table."""
    cols = list(rows[0].keys())
    with open(path, "w") as f:
        f.write(f"# {title}\n\n{intro}\n\n")
        f.write("| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n")
        for r in rows:
            f.write("| " + " | ".join(r[c] for c in cols) + " |\n")


def pyplot():
    """matplotlib's pyplot without a display, or None where it is missing."""
    try:
        import matplotlib
    except ImportError:
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt
