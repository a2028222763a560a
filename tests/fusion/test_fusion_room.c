/* fusion end to end: a short synthetic room sequence with Kinect v1 noise,
 * fused with its true poses, exported as surface voxels and measured
 * against the reference mesh (issue 3's check, at test size: 36 frames of
 * 320x240 instead of 300 of 640x480; bench/fusion_sweep.sh runs the full
 * size). Validation is on. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eval/eval.h"
#include "mesh/mesh.h"
#include "synth/synth.h"
#include "fusion/fusion.h"
#include "fusion/fusion_int.h"
#include "gpu_fixture.h"
#include "replay/replay.h"
#include "export/export.h"
#include "render/render.h"
#include "shaders/fusion.glsl.h"

/* A hand-held sideways sweep with a little yaw, 100 Hz, first pose the
 * identity (synth places it at the room's viewpoint). */
static void write_sweep(const char *path)
{
    bf_traj t = {0};
    for (int k = 0; k <= 250; k++) {
        double s = k / 100.0;
        bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.15 * sin(s)),
                                  bf_v3(0.25 * sin(s), 0.02 * sin(3 * s), 0.05 * (1 - cos(s))));
        bf_traj_push(&t, 100.0 + s, &T);
    }
    replay_traj_write_tum(path, &t);
    bf_traj_free(&t);
}

/* The room without the shared meshes (walls, table and boxes: no test
 * depends on ../shared/data), n frames of the sweep at 320x240 with Kinect
 * v1 noise of the given seed, written to seq (the test folder's name). */
static void synth_room(const char *name, uint32_t n, uint64_t seed, char seq[512])
{
    char traj[600];
    snprintf(traj, sizeof traj, "%s/%s_sweep.txt", bf_test_tmpdir(), name);
    snprintf(seq, 512, "%s/%s", bf_test_tmpdir(), name);
    write_sweep(traj);
    synth_config sc = {.scene = "room", .traj_path = traj, .n_frames = n, .noise = SYNTH_NOISE_KINECT1,
                       .seed = seed, .K = {320, 240, 262.5, 262.5, 159.5, 119.5, 5000}, .out_dir = seq};
    CHECK_OK(synth_run(&sc, NULL));
}

/* The scene's colour (0..255 per channel) at its point closest to p
 * within 2 cm, seen along view; false when none is that close. */
static bool scene_colour_near(const synth_scene *scene, const mesh_bvh *bvh, bf_vec3 p, bf_vec3 view, double rgb[3])
{
    bf_vec3 q;
    uint32_t tri;
    if (!(mesh_bvh_closest(bvh, p, 0.02, &q, &tri) < 0.02)) return false;
    const uint32_t *tv = scene->mesh.tri + 3 * (size_t)tri;
    const float *x = scene->mesh.xyz;
    bf_vec3 a = bf_v3(x[3 * tv[0]], x[3 * tv[0] + 1], x[3 * tv[0] + 2]);
    bf_vec3 b = bf_v3(x[3 * tv[1]], x[3 * tv[1] + 1], x[3 * tv[1] + 2]);
    bf_vec3 c = bf_v3(x[3 * tv[2]], x[3 * tv[2] + 1], x[3 * tv[2] + 2]);
    /* Barycentrics of q (Ericson, Real-Time Collision Detection 3.4). */
    bf_vec3 e0 = bf_v3_sub(b, a), e1 = bf_v3_sub(c, a), e2 = bf_v3_sub(q, a);
    double d00 = bf_v3_dot(e0, e0), d01 = bf_v3_dot(e0, e1), d11 = bf_v3_dot(e1, e1);
    double d20 = bf_v3_dot(e2, e0), d21 = bf_v3_dot(e2, e1), den = d00 * d11 - d01 * d01;
    double u = den != 0 ? (d11 * d20 - d01 * d21) / den : 0, v = den != 0 ? (d00 * d21 - d01 * d20) / den : 0;
    synth_scene_shade(scene, tri, u, v, q, view, rgb);
    for (int k = 0; k < 3; k++) rgb[k] = fmin(fmax(rgb[k], 0), 1) * 255.0;
    return true;
}

/* ---- the colour trim's oracle (shaders/fusion_colour.comp, trim_masks) */

/* The voxel at global voxel coordinates g of level `level` in sorted map m:
 * its brick's index (-1: none at this level) and, through *cs, bit 1
 * confident and bit 0 its sign. */
static long trim_voxel(const hostmap *m, uint32_t level, const int64_t g[3], uint32_t *cs)
{
    hostmap_brick want = {.level = level};
    int64_t n = (int64_t)1 << level;
    uint32_t x[3];
    for (int a = 0; a < 3; a++) {
        int64_t b = g[a] >= 0 ? g[a] / 8 : -((-g[a] + 7) / 8);
        int64_t key = b >= 0 ? b / n : -((-b + n - 1) / n);
        want.key[a] = (int32_t)key, want.cell[a] = (uint32_t)(b - key * n), x[a] = (uint32_t)(g[a] - b * 8);
    }
    *cs = 0;
    const hostmap_brick *hit = bsearch(&want, m->bricks, m->n_bricks, sizeof *m->bricks,
                                       (int (*)(const void *, const void *))hostmap_brick_cmp);
    if (!hit) return -1;
    uint32_t w = brick_word(x[0], x[1], x[2]), bit = brick_bit(x[0], x[1], x[2]);
    *cs = (((hit->conf[w] >> bit) & 1u) << 1) | ((hit->sign[w] >> bit) & 1u);
    return hit - m->bricks;
}

/* Confident with a confident face neighbour of the other sign, or one in a
 * brick this level does not have; only the neighbours in bricks a or b
 * count when only_ab (a voxel of a neighbouring brick, which the pass sees
 * through its face layers alone). */
static bool trim_s1(const hostmap *m, uint32_t level, const int64_t g[3], bool only_ab, long a, long b)
{
    uint32_t c, d;
    trim_voxel(m, level, g, &c);
    if (c < 2) return false;
    for (int f = 0; f < 6; f++) {
        int64_t q[3] = {g[0], g[1], g[2]};
        q[f / 2] += f % 2 ? 1 : -1;
        long at = trim_voxel(m, level, q, &d);
        if (only_ab && at != a && at != b) continue;
        if (at < 0 || (d >= 2 && d != c)) return true;
    }
    return false;
}

/* Whether the trim with reach k keeps voxel (x, y, z) of brick i. */
static bool trim_keeps(const hostmap *m, long i, uint32_t x, uint32_t y, uint32_t z, uint32_t k)
{
    const hostmap_brick *br = &m->bricks[i];
    int64_t n = (int64_t)1 << br->level, g[3];
    uint32_t v[3] = {x, y, z};
    for (int a = 0; a < 3; a++) g[a] = ((int64_t)br->key[a] * n + br->cell[a]) * 8 + v[a];
    if (trim_s1(m, br->level, g, false, i, i)) return true;
    uint32_t c;
    trim_voxel(m, br->level, g, &c);
    if (k < 2 || c < 2) return false;
    for (int f = 0; f < 6; f++) {
        int64_t q[3] = {g[0], g[1], g[2]};
        q[f / 2] += f % 2 ? 1 : -1;
        uint32_t d;
        long at = trim_voxel(m, br->level, q, &d);
        if (at < 0) continue;
        if (trim_s1(m, br->level, q, at != i, i, at)) return true;
    }
    return false;
}

/* The colours of `trimmed` are those of `whole` where the trim with reach k
 * keeps a voxel, none elsewhere, bit for bit (the same frames fused into
 * both, the trim at the end alone). */
static void check_trim(hostmap *whole, hostmap *trimmed, uint32_t k)
{
    CHECK_OK(hostmap_sort(whole));
    CHECK_OK(hostmap_sort(trimmed));
    CHECK_EQ_INT(whole->n_bricks, trimmed->n_bricks);
    uint64_t n_whole = 0, n_kept = 0, n_wrong = 0;
    for (long i = 0; i < (long)whole->n_bricks; i++) {
        CHECK(hostmap_brick_cmp(&whole->bricks[i], &trimmed->bricks[i]) == 0);
        for (uint32_t v = 0; v < 512; v++) {
            uint16_t c = whole->rgb565[(size_t)i * 512 + v], t = trimmed->rgb565[(size_t)i * 512 + v];
            n_whole += c != 0;
            uint16_t want = c && trim_keeps(whole, i, v % 8, (v / 8) % 8, v / 64, k) ? c : 0;
            n_kept += want != 0, n_wrong += t != want;
        }
    }
    fprintf(stderr, "  colour trim, reach %u: %llu of %llu colours kept, %llu differ from the oracle's\n", k,
            (unsigned long long)n_kept, (unsigned long long)n_whole, (unsigned long long)n_wrong);
    CHECK_EQ_INT(n_wrong, 0);
    CHECK(n_kept > 0 && n_kept < n_whole);
}

/* A brick's place (key, level, cell) and its stamp, sorted as hostmap_sort
 * sorts the bricks. */
typedef struct trim_stamp {
    hostmap_brick id;
    uint32_t stamp;
} trim_stamp;
static int trim_stamp_cmp(const void *a, const void *b)
{
    return hostmap_brick_cmp(&((const trim_stamp *)a)->id, &((const trim_stamp *)b)->id);
}

/* The first n frames of the room into a new map *out of config fc (no
 * flush: the state right after frame n - 1's fusion_add_frame); *st its
 * stats. */
static void fuse_room_frames(gpu_context *ctx, const char *seq, const fusion_config *fc, uint32_t n, fusion_stats *st,
                             fusion_map **out)
{
    rgbd_source *src;
    CHECK_OK(replay_open(seq, NULL, &src));
    fusion_map *map = NULL;
    *out = NULL;
    bf_frame f;
    for (uint32_t i = 0; i < n; i++) {
        CHECK_OK(rgbd_source_next(src, &f));
        if (!map) CHECK_OK(fusion_create(ctx, fc, rgbd_source_intrinsics(src), f.T_wc.t, &map));
        CHECK_OK(fusion_add_frame(map, &f, &f.T_wc));
    }
    rgbd_source_close(src);
    *out = map;
    CHECK_OK(fusion_check(map));
    CHECK_OK(fusion_get_stats(map, st));
}

/* The room's frames fused into a map of config fc; its snapshot and stats. */
static void fuse_room(gpu_context *ctx, const char *seq, const fusion_config *fc, hostmap *snap, fusion_stats *st)
{
    rgbd_source *src;
    CHECK_OK(replay_open(seq, NULL, &src));
    fusion_map *map = NULL;
    bf_frame f;
    bf_status s;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        if (!map) CHECK_OK(fusion_create(ctx, fc, rgbd_source_intrinsics(src), f.T_wc.t, &map));
        CHECK_OK(fusion_add_frame(map, &f, &f.T_wc));
    }
    CHECK_STATUS(s, BF_END);
    CHECK_OK(fusion_flush(map));
    CHECK_OK(fusion_check(map)); /* the colour chains and free stack too */
    CHECK_OK(fusion_get_stats(map, st));
    CHECK_OK(fusion_snapshot_take(map, snap));
    fusion_destroy(map);
    rgbd_source_close(src);
}

BF_TEST(fused_room_surface_is_within_a_voxel_and_covers_what_was_seen)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    char seq[512], path[600];
    synth_room("room", 36, 3, seq);

    rgbd_source *src;
    CHECK_OK(replay_open(seq, NULL, &src));
    fusion_config fc = fusion_config_default();
    fc.brick_cap = 1u << 17;
    fusion_map *map = NULL;
    bf_frame f;
    bf_status s;
    bf_se3 T_last = bf_se3_identity();
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        CHECK(f.has_pose);
        T_last = f.T_wc;
        if (!map) CHECK_OK(fusion_create(ctx, &fc, rgbd_source_intrinsics(src), f.T_wc.t, &map));
        CHECK_OK(fusion_add_frame(map, &f, &f.T_wc));
    }
    CHECK_STATUS(s, BF_END);
    CHECK_OK(fusion_flush(map));
    CHECK_OK(fusion_check(map));
    fusion_stats st;
    CHECK_OK(fusion_get_stats(map, &st));
    /* Memory: 2 bits of sign and confidence per voxel plus records, nodes
     * and hash must stay under 3 bits per allocated voxel, a tenth of a
     * 4-byte TSDF. */
    CHECK(st.n_bricks > 1000);
    CHECK_LE(8.0 * (double)st.bytes_total / (512.0 * st.n_bricks), 3.0);
    /* The level most of the surface sits on (half-resolution frames put it
     * one level coarser than 640x480 would). */
    uint32_t typical = 0;
    for (uint32_t l = 0; l < 16; l++)
        if (st.bricks_per_level[l] > st.bricks_per_level[typical]) typical = l;

    hostmap snap;
    CHECK_OK(fusion_snapshot_take(map, &snap));
    mesh_data pts = {0}, ref = {0}, seen = {0};
    CHECK_OK(export_points(&snap, &pts, NULL));
    snprintf(path, sizeof path, "%s/scene.ply", seq);
    CHECK_OK(mesh_read_ply(path, &ref));
    snprintf(path, sizeof path, "%s/seen.ply", seq);
    CHECK_OK(mesh_read_ply(path, &seen));
    eval_surface_config ec = eval_surface_config_default();
    eval_surface_result er;
    CHECK_OK(eval_surface(&ref, &pts, &seen, &ec, &er));
    double voxel = hostmap_level_voxel_m(fc.chunk_m, typical);
    fprintf(stderr, "  %u bricks (most at level %u, %.1f mm), %u surface points: median %.2f mm, p90 %.2f mm, "
                    "completeness %.1f%%\n",
            st.n_bricks, typical, 1e3 * voxel, pts.n_verts, 1e3 * er.accuracy.median, 1e3 * er.accuracy.p90,
            100 * er.completeness);
    /* Issue 3's bounds at test size: surface voxel centres lie within one
     * voxel of the surface's level (median; a centre next to a sign change is
     * at most one voxel away from it, half a voxel on average), and 90% of the
     * seen surface has a surface voxel within 1 cm. The 5 mm bound of the
     * issue holds for 640x480 frames (finer levels): bench/fusion_sweep.sh. */
    CHECK_LE(er.accuracy.median, voxel);
    CHECK(er.completeness >= 0.90);

    /* Colour: every surface point's colour against what the renderer gives
     * the closest point of the scene (view-independent shading), in 8-bit
     * levels, mean over the channels. */
    CHECK(snap.rgb565 != NULL && pts.rgb != NULL);
    synth_scene scene;
    CHECK_OK(synth_scene_room(NULL, &scene));
    mesh_bvh *bvh;
    CHECK_OK(mesh_bvh_build(&scene.mesh, &bvh));
    double *err = calloc(pts.n_verts, sizeof *err);
    uint32_t n_err = 0, n_grey = 0;
    for (uint32_t i = 0; i < pts.n_verts; i++) {
        bf_vec3 p = bf_v3(pts.xyz[3 * i], pts.xyz[3 * i + 1], pts.xyz[3 * i + 2]);
        bf_vec3 view = bf_v3(-pts.normal[3 * i], -pts.normal[3 * i + 1], -pts.normal[3 * i + 2]);
        double rgb[3];
        if (!scene_colour_near(&scene, bvh, p, view, rgb)) continue;
        double e = 0;
        for (int k = 0; k < 3; k++) e += fabs(rgb[k] - pts.rgb[3 * i + k]) / 3.0;
        n_grey += pts.rgb[3 * i] == 160 && pts.rgb[3 * i + 1] == 160 && pts.rgb[3 * i + 2] == 160;
        err[n_err++] = e;
    }
    CHECK(n_err > pts.n_verts / 2);
    double med = bf_percentile_inplace(err, n_err, 50);
    fprintf(stderr, "  colour: %u points, %u uncoloured, %.2f bits/voxel of colour, median error %.2f levels\n",
            n_err, n_grey, 8.0 * (double)st.bytes_colour / (512.0 * st.n_bricks), med);
    /* RGB565 alone is off by 1-2 levels on average (4 and 8 levels per
     * step), the sensor's colour noise (1.5 levels) averages out over the
     * window, and texture varies inside a 7.8 mm voxel: 2.4 levels measured,
     * bounded at 6. Points without any coloured voxel near them (grey):
     * under 2%. Colour costs 4.0 bits per allocated voxel here (masks 1.06,
     * units of 14 colours for the coloured voxels; docs/colour.md): bounded
     * at 6 to catch growth. */
    CHECK_LE(med, 6.0);
    CHECK_LE(n_grey, n_err / 50);
    CHECK_LE(8.0 * (double)st.bytes_colour / (512.0 * st.n_bricks), 6.0);

    /* The colour trim (36 frames, one window: at the end alone) against its
     * oracle, for the default reach (this map) and the other one, from the
     * same frames fused without it; the units it gives back. Then windows
     * of 8 frames (trims mid-scan too, and colour taken again after them):
     * the chains stay whole (fusion_check). */
    {
        CHECK(fc.colour_reach == 1 || fc.colour_reach == 2);
        fusion_config f0 = fc, fo = fc, f8 = fc;
        f0.colour_reach = 0, fo.colour_reach = 3 - fc.colour_reach, f8.window = 8, f8.subcache = 8;
        hostmap whole = {0}, other = {0}, eight = {0};
        fusion_stats s0, so, s8;
        fuse_room(ctx, seq, &f0, &whole, &s0);
        fuse_room(ctx, seq, &fo, &other, &so);
        fuse_room(ctx, seq, &f8, &eight, &s8);
        check_trim(&whole, &snap, fc.colour_reach);
        check_trim(&whole, &other, fo.colour_reach);
        uint32_t units1 = fc.colour_reach == 1 ? st.n_colour_units : so.n_colour_units;
        uint32_t units2 = fc.colour_reach == 2 ? st.n_colour_units : so.n_colour_units;
        /* Every colour left after the mid-scan trims passes the rule. */
        CHECK_OK(hostmap_sort(&eight));
        uint64_t n8 = 0, bad8 = 0;
        for (long i = 0; i < (long)eight.n_bricks; i++)
            for (uint32_t v = 0; v < 512; v++)
                if (eight.rgb565[(size_t)i * 512 + v])
                    n8++, bad8 += !trim_keeps(&eight, i, v % 8, (v / 8) % 8, v / 64, f8.colour_reach);
        CHECK(n8 > 0);
        CHECK_EQ_INT(bad8, 0);
        /* Mid-scan: windows of 8 frames (slide 4) stopped right after frame
         * 23 closed one: its gathering trimmed the bricks stamped last by
         * frames 12-15, and no slice of the new window [16, 23] has run.
         * Those bricks pass the rule; the new window's still hold colour
         * past it (they are integrated again, and trimmed when left); the
         * units are fewer than without the trim at the same frame. */
        {
            fusion_config fw = fc, fw0 = fc;
            fw.window = fw0.window = 8, fw.subcache = fw0.subcache = 8, fw0.colour_reach = 0;
            fusion_stats sw, sw0;
            fusion_map *mw, *mw0;
            fuse_room_frames(ctx, seq, &fw, 24, &sw, &mw);
            fuse_room_frames(ctx, seq, &fw0, 24, &sw0, &mw0);
            CHECK_EQ_INT(mw->window_first, 16);
            hostmap ms = {0};
            CHECK_OK(fusion_snapshot_take(mw, &ms));
            /* The stamps in the snapshot's order (live slots ascending). */
            uint32_t cap = fw.brick_cap;
            uint32_t *info = malloc((size_t)cap * FUSION_BRICK_INFO_WORDS * 4), *stamp = malloc((size_t)cap * 4);
            trim_stamp *ts = calloc(ms.n_bricks + 1, sizeof *ts);
            CHECK(info && stamp && ts);
            CHECK_OK(gpu_buffer_download(mw->info, 0, info, (uint64_t)cap * FUSION_BRICK_INFO_WORDS * 4));
            CHECK_OK(gpu_buffer_download(mw->stamp, 0, stamp, (uint64_t)cap * 4));
            uint32_t k = 0;
            for (uint32_t b = 0; b < cap && k < ms.n_bricks; b++)
                if (info[(size_t)b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] < mw->n_entries)
                    ts[k].id = ms.bricks[k], ts[k].stamp = stamp[b], k++;
            CHECK_EQ_INT(k, ms.n_bricks);
            CHECK_OK(hostmap_sort(&ms));
            qsort(ts, ms.n_bricks, sizeof *ts, trim_stamp_cmp);
            uint64_t n_left = 0, bad_left = 0, n_window = 0, past_window = 0;
            for (long i = 0; i < (long)ms.n_bricks; i++) {
                CHECK(hostmap_brick_cmp(&ts[i].id, &ms.bricks[i]) == 0);
                bool left = ts[i].stamp >= 12 && ts[i].stamp <= 15, in_window = ts[i].stamp >= 16 && ts[i].stamp != FUSION_NONE;
                for (uint32_t v = 0; v < 512; v++) {
                    if (!ms.rgb565[(size_t)i * 512 + v] || !(left || in_window)) continue;
                    bool keeps = trim_keeps(&ms, i, v % 8, (v / 8) % 8, v / 64, fw.colour_reach);
                    if (left) n_left++, bad_left += !keeps;
                    else n_window++, past_window += !keeps;
                }
            }
            fprintf(stderr, "  mid-scan (windows of 8, after frame 23): bricks left at frames 12-15: %llu colours, %llu "
                            "past the reach; the new window's: %llu, %llu past it; units %u (%u without the trim)\n",
                    (unsigned long long)n_left, (unsigned long long)bad_left, (unsigned long long)n_window,
                    (unsigned long long)past_window, sw.n_colour_units, sw0.n_colour_units);
            CHECK(n_left > 0 && n_window > 0);
            CHECK_EQ_INT(bad_left, 0);
            CHECK(past_window > 0);
            CHECK(sw.n_colour_units < sw0.n_colour_units);
            free(info);
            free(stamp);
            free(ts);
            hostmap_free(&ms);
            fusion_destroy(mw);
            fusion_destroy(mw0);
        }
        /* A map loaded untrimmed (a store written before the trim), then
         * one frame and the end of the scan: the loaded bricks are trimmed
         * too. */
        {
            fusion_map *lm = NULL;
            rgbd_source *ls;
            bf_frame lf;
            CHECK_OK(replay_open(seq, NULL, &ls));
            CHECK_OK(rgbd_source_next(ls, &lf));
            CHECK_OK(fusion_create(ctx, &fc, rgbd_source_intrinsics(ls), whole.origin_w, &lm));
            CHECK_OK(fusion_load(lm, &whole));
            CHECK_OK(fusion_add_frame(lm, &lf, &lf.T_wc));
            CHECK_OK(fusion_flush(lm));
            CHECK_OK(fusion_check(lm));
            hostmap lt = {0};
            CHECK_OK(fusion_snapshot_take(lm, &lt));
            CHECK_OK(hostmap_sort(&lt));
            uint64_t nl = 0, badl = 0;
            for (long i = 0; i < (long)lt.n_bricks; i++)
                for (uint32_t v = 0; v < 512; v++)
                    if (lt.rgb565[(size_t)i * 512 + v]) nl++, badl += !trim_keeps(&lt, i, v % 8, (v / 8) % 8, v / 64, fc.colour_reach);
            fprintf(stderr, "  loaded untrimmed, one frame, flushed: %llu colours, %llu past the reach\n",
                    (unsigned long long)nl, (unsigned long long)badl);
            CHECK(nl > 0);
            CHECK_EQ_INT(badl, 0);
            hostmap_free(&lt);
            fusion_destroy(lm);
            rgbd_source_close(ls);
        }
        fprintf(stderr, "  colour units: %u without the trim, %u reach 2, %u reach 1; windows of 8: %u\n",
                s0.n_colour_units, units2, units1, s8.n_colour_units);
        CHECK(units2 < s0.n_colour_units && units1 < units2);
        hostmap_free(&whole);
        hostmap_free(&other);
        hostmap_free(&eight);
    }

    /* The ray-cast's colour lookup (popcount rank along the brick's chain
     * of units, on the GPU) against the same scene colours, at the last
     * frame's pose: what --view-every images show. */
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    render_caster *rc;
    CHECK_OK(render_create(ctx, NULL, K->width, K->height, &rc));
    render_options ro = render_options_display();
    CHECK_OK(render_raycast(rc, map, K, &T_last, &ro));
    size_t n_px = (size_t)K->width * K->height;
    float *depth = malloc(n_px * 4);
    uint32_t *c565 = malloc(n_px * 4);
    double *err_view = calloc(n_px, sizeof *err_view);
    CHECK_OK(gpu_buffer_download(render_get_targets(rc)->depth, 0, depth, n_px * 4));
    CHECK_OK(gpu_buffer_download(render_get_targets(rc)->surface_rgb, 0, c565, n_px * 4));
    uint32_t n_hit = 0, n_none = 0, n_cmp = 0;
    for (size_t i = 0; i < n_px; i++) {
        if (!(depth[i] > 0)) continue;
        n_hit++;
        if (!c565[i]) {
            n_none++;
            continue;
        }
        double u = (double)(i % K->width), v = (double)(i / K->width), z = depth[i];
        bf_vec3 pc = bf_v3((u - K->cx_px) / K->fx_px * z, (v - K->cy_px) / K->fy_px * z, z);
        bf_vec3 p = bf_se3_apply(&T_last, pc);
        double rgb[3];
        if (!scene_colour_near(&scene, bvh, p, bf_v3_sub(p, T_last.t), rgb)) continue;
        uint32_t got[3] = {bf_565_r(c565[i]), bf_565_g(c565[i]), bf_565_b(c565[i])};
        double e = 0;
        for (int k = 0; k < 3; k++) e += fabs(rgb[k] - got[k]) / 3.0;
        err_view[n_cmp++] = e;
    }
    double med_view = n_cmp ? bf_percentile_inplace(err_view, n_cmp, 50) : 1e9;
    fprintf(stderr, "  ray-cast colour: %u hits, %u without colour, median error %.2f levels over %u\n", n_hit,
            n_none, med_view, n_cmp);
    /* Hits lie within a voxel of the surface and the cast looks half a
     * voxel to either side for a coloured voxel: nearly every hit has one;
     * the colours are the map's, so the same bound as the points'. */
    CHECK(n_hit > n_px / 4);
    CHECK_LE(n_none, n_hit / 50);
    CHECK(n_cmp > n_hit / 2);
    CHECK_LE(med_view, 6.0);
    free(depth);
    free(c565);
    free(err_view);
    render_destroy(rc);
    free(err);
    mesh_bvh_destroy(bvh);
    synth_scene_free(&scene);
    mesh_free(&pts);
    mesh_free(&ref);
    mesh_free(&seen);
    hostmap_free(&snap);
    fusion_destroy(map);
    rgbd_source_close(src);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* Surface voxels (export_points) of the first n frames of seq fused at
 * their true poses and flushed: a sequence that short is one window. */
static void short_sequence_surface(gpu_context *ctx, const char *seq, uint32_t n, uint32_t *n_pts)
{
    *n_pts = 0;
    fusion_config fc = fusion_config_default();
    fc.brick_cap = 1u << 16;
    fusion_map *map;
    fusion_stats st;
    fuse_room_frames(ctx, seq, &fc, n, &st, &map);
    CHECK_OK(fusion_flush(map));
    hostmap snap;
    CHECK_OK(fusion_snapshot_take(map, &snap));
    mesh_data pts = {0};
    CHECK_OK(export_points(&snap, &pts, NULL));
    *n_pts = pts.n_verts;
    mesh_free(&pts);
    hostmap_free(&snap);
    fusion_destroy(map);
}

/* A sequence of a few frames is fused as one window of that many frames.
 * Its confidence threshold was capped at the frame count, which asked a
 * voxel to be seen with full weight in every frame: the voxels just behind
 * a noisy surface rarely are, and 2-4 frames of a nearly still camera kept
 * a sixth of the surface one frame kept (the QA pass of the forty-fifth
 * session: 67,066 surface voxels from one frame, 9,901 from four). Half the
 * frames' weight is asked now; more frames of the same view may not lose
 * what fewer kept. */
BF_TEST(a_few_frames_keep_the_surface_one_frame_keeps)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    char seq[512];
    synth_room("room_short", 4, 5, seq);
    uint32_t n1, n2, n4;
    short_sequence_surface(ctx, seq, 1, &n1);
    short_sequence_surface(ctx, seq, 2, &n2);
    short_sequence_surface(ctx, seq, 4, &n4);
    fprintf(stderr, "  surface voxels from 1, 2 and 4 frames: %u, %u, %u\n", n1, n2, n4);
    CHECK(n1 > 1000);
    CHECK(n2 >= 0.8 * n1);
    CHECK(n4 >= 0.8 * n1);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}
