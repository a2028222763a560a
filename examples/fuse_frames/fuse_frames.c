/* fuse_frames: bitfuse as a library. Fuses the first N frames of a
 * sequence (a TUM folder, ICL-NUIM, a pose folder or a .bflog) at its
 * ground-truth poses into the sign-bit map and prints what the map holds.
 *
 *   fuse_frames SEQUENCE [N]
 *
 * Built against an installed bitfuse (examples/fuse_frames/CMakeLists.txt,
 * or pkg-config --cflags --libs bitfuse); exit 0 when at least one frame
 * was fused, 1 otherwise, the message on stderr. */
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>

#include "core/core.h"
#include "fusion/fusion.h"
#include "gpu/gpu.h"
#include "recon/recon.h"
#include "replay/replay.h"

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: fuse_frames SEQUENCE [N]\n");
        return 2;
    }
    replay_options opt = {.max_frames = argc > 2 ? (uint32_t)atoi(argv[2]) : 3};
    rgbd_source *src = NULL;
    gpu_context *ctx = NULL;
    recon_run run = {0};
    gpu_config gcfg = {0};
    /* The input first, then the device: a bad path costs no device start. */
    bf_status s = replay_open(argv[1], &opt, &src);
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    if (s == BF_OK) {
        recon_run_config cfg = recon_run_config_default();
        cfg.poses = RECON_POSES_KNOWN; /* the frames' own ground truth */
        cfg.loop.fusion.brick_cap = 1u << 15; /* a few frames: small pools start fast */
        cfg.name = argv[1];
        cfg.label = "fuse_frames";
        s = recon_run_sequence(ctx, src, &cfg, NULL, NULL, &run);
    }
    fusion_stats st;
    if (s == BF_OK) s = fusion_get_stats(run.map, &st);
    if (s == BF_OK)
        printf("fuse_frames: %u frames fused on %s: %u bricks, %llu surface voxels\n", run.n_fused,
               gpu_device_name(ctx), st.n_bricks, (unsigned long long)st.n_surface_voxels);
    else
        fprintf(stderr, "fuse_frames: %s\n", bf_last_error());
    bool is_fused = s == BF_OK && run.n_fused > 0;
    recon_run_free(&run);
    gpu_context_destroy(ctx);
    rgbd_source_close(src);
    return is_fused ? 0 : 1;
}
