/* Soak run of the full loop (issue 4): N frames (default 10,000) of a
 * synthetic room, rendered once into memory along a closed hand-held loop
 * and fed to the loop back and forth (ping-pong, so the motion stays
 * continuous), with the time per frame, the process's resident memory and
 * the map's bytes reported per block of frames. Time per frame and memory
 * must not grow beyond what the map itself needs.
 *
 * Under faults (issue 15): --drop P drops each frame with probability P
 * (the next one comes later, as from a camera that lost frames), --zero
 * N/E gives N frames of zero depth every E frames (a covered lens), and a
 * small --cache-mib with a short --stream-radius sends chunks to the
 * stream's spill folder (under $TMPDIR); run under tests/fault's shim with
 * FAULT_DIR=$TMPDIR FAULT_DELAY_US=D for a slow disk (docs/faults.md).
 *
 * --scene rooms:N walks down a row of N rooms (synth_scene_rooms) and back
 * instead (bench/rooms_walk.py's walk, --step metres per frame), so chunks
 * leave the stream's reach, go to the cache and the spill folder, and come
 * back on the way back; the TSV counts them per block.
 *
 *   bench_soak [--frames N] [--loop M] [--size WxH] [--block B] [--out FILE.tsv]
 *              [--drop P] [--zero N/E] [--seed S] [--stream-radius M] [--cache-mib C]
 *              [--scene room|rooms:N] [--step M]
 */
#include <malloc.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "synth/synth.h"
#include "recon/recon.h"

static double rss_mib(void)
{
    FILE *f = fopen("/proc/self/statm", "r");
    long pages = 0, resident = 0;
    if (f) {
        if (fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
        fclose(f);
    }
    return resident * (double)sysconf(_SC_PAGESIZE) / 1048576.0;
}

/* The machine's load (1-minute average): time per frame on a shared
 * machine follows it. */
static double load_avg(void)
{
    double l = -1;
    FILE *f = fopen("/proc/loadavg", "r");
    if (f) {
        if (fscanf(f, "%lf", &l) != 1) l = -1;
        fclose(f);
    }
    return l;
}

/* Bytes malloc holds for the process (in use, arenas and mmapped blocks):
 * what grows with live allocations, unlike RSS it leaves out the driver's
 * and the pools' mappings. */
static double heap_mib(void)
{
    struct mallinfo2 mi = mallinfo2();
    return (mi.uordblks + mi.hblkhd) / 1048576.0;
}

/* The run's per-frame records, which grow by design (recon_run: the
 * estimated and true trajectories and the per-frame time series): their
 * allocated bytes. */
static double records_mib(const recon_run *run)
{
    const recon_run_series *se = &run->series;
    const bf_stats *st[] = {&se->frame_ms, &se->track_ms,  &se->inlier_frac, &se->residual_mm,
                            &se->rof_ms,   &se->raycast_ms, &se->upload_ms,  &se->alloc_ms,
                            &se->subcache_ms, &se->window_ms, &se->colour_ms};
    double b = (double)(run->est.cap + run->gt.cap) * (sizeof(double) + sizeof(bf_se3));
    for (size_t i = 0; i < sizeof st / sizeof *st; i++) b += (double)st[i]->cap * sizeof(double);
    return b / 1048576.0;
}

/* A closed hand-held loop: sway, bob and yaw, period M frames. */
static bf_se3 loop_pose(const synth_scene *sc, uint32_t k, uint32_t m)
{
    double w = 2 * M_PI * k / m;
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.2 * sin(w)),
                              bf_v3(0.35 * sin(w), 0.03 * sin(2 * w), 0.15 * (1 - cos(w))));
    return bf_se3_mul(&sc->T_wc_view, &M);
}

/* The walk down a row of rooms (bench/rooms_walk.py's, out only: the
 * ping-pong brings it back): the camera's +z is forward, step metres a
 * frame, looking left and right by sway_deg over 120 frames. Its length
 * runs from the first room to 1 m into the last; m = walk_frames(). */
static uint32_t walk_frames(uint32_t rooms, double step)
{
    return (uint32_t)lround(((rooms - 1) * 4.0 + 1.0) / step) + 1;
}

static bf_se3 walk_pose(const synth_scene *sc, uint32_t k, double step)
{
    const double sway_rad = 15.0 * M_PI / 180.0;
    double yaw = sway_rad * sin(2 * M_PI * k / 120.0);
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), yaw), bf_v3(0, 0, k * step));
    return bf_se3_mul(&sc->T_wc_view, &M);
}

/* The frames, rendered once: frame i plays loop frame k of a ping-pong
 * through the loop (0..m-1, m-2..1, 0..), so the motion stays continuous. */
typedef struct soak_frames {
    const bf_se3 *pose;    /* m true poses */
    const uint16_t *depth; /* m frames of w x h */
    const uint16_t *zero;  /* one frame of zero depth */
    uint32_t m, w, h;
    const uint32_t *tick;  /* frame i of the source is camera tick tick[i] (drops skip ticks) */
    uint32_t zero_n, zero_every; /* zero_n frames of zero depth every zero_every ticks */
} soak_frames;

static bf_status soak_frame(void *user, uint32_t i, bf_frame *f)
{
    const soak_frames *sf = user;
    uint32_t c = sf->tick[i];
    uint32_t period = 2 * (sf->m - 1), p = c % period, k = p < sf->m ? p : period - p;
    bool zero = sf->zero_every && c % sf->zero_every >= sf->zero_every - sf->zero_n;
    *f = (bf_frame){.index = i, .width = sf->w, .height = sf->h, .t_depth_s = c / 30.0,
                    .depth = zero ? sf->zero : sf->depth + (size_t)sf->w * sf->h * k, .has_pose = true,
                    .T_wc = sf->pose[k]};
    f->t_rgb_s = f->t_depth_s;
    return BF_OK;
}

/* The camera ticks the source delivers: n of them, each tick dropped with
 * probability drop (xorshift64, seeded). */
static uint32_t *soak_ticks(uint32_t n, double drop, uint64_t seed, uint32_t *dropped)
{
    uint32_t *t = malloc((size_t)n * sizeof *t);
    uint64_t x = seed * 2654435761u + 88172645463325252ull;
    *dropped = 0;
    for (uint32_t i = 0, c = 0; t && i < n; c++) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        if ((x >> 11) * (1.0 / 9007199254740992.0) < drop) {
            (*dropped)++;
            continue;
        }
        t[i++] = c;
    }
    return t;
}

/* One line per block of frames: time, memory, map, tracking. */
typedef struct soak_report {
    FILE *out, *trace; /* trace: one line per frame (--trace), or NULL */
    const soak_frames *sf;
    uint32_t n, block;
    bf_stats ms;
    double max_err, t_start;
    stream_stats last; /* at the end of the previous block: spills and reloads per block */
} soak_report;

static bf_status soak_on_frame(void *user, recon_run *run, const bf_frame *f, const recon_frame_result *fr)
{
    soak_report *sr = user;
    uint32_t i = f->index;
    /* The error of the frames the loop placed (a frame without depth keeps
     * the last pose while the camera moves on). */
    double err = bf_v3_norm(bf_v3_sub(f->T_wc.t, fr->T_wc.t));
    bool placed = fr->state == RECON_TRACKED || fr->state == RECON_RELOCALISED || fr->state == RECON_FIRST;
    if (placed && err > sr->max_err) sr->max_err = err;
    if (sr->trace) {
        uint32_t c = sr->sf->tick[i], period = 2 * (sr->sf->m - 1), p = c % period;
        fprintf(sr->trace, "%u\t%u\t%u\t%s\t%.2f\t%.1f\t%.2f\t%.2f\n", i, c, p < sr->sf->m ? p : period - p,
                recon_state_name(fr->state), 1e3 * err, 100 * fr->track.inlier_frac, fr->ms_frame, fr->ms_stream);
    }
    bf_status s = bf_stats_push(&sr->ms, fr->ms_frame);
    if (s != BF_OK || ((i + 1) % sr->block != 0 && i + 1 != sr->n)) return s;
    fusion_stats st;
    if ((s = fusion_get_stats(run->map, &st)) != BF_OK) return s;
    recon_counts c = run->counts;
    stream_stats ss = run->loop ? recon_stream_stats(run->loop) : (stream_stats){0};
    fprintf(sr->out,
            "%u\t%.2f\t%.2f\t%.1f\t%.2f\t%u\t%u\t%u\t%.2f\t%u\t%u\t%llu\t%llu\t%llu\t%llu\t%llu\t%llu\t%llu\t%u\t"
            "%.3f\t%u\t%.2f\t%.2f\t%.2f\n",
            i + 1, bf_stats_percentile(&sr->ms, 50), bf_stats_percentile(&sr->ms, 95), rss_mib(),
            st.bytes_total / 1048576.0, st.n_bricks, c.tracked, c.lost, 1e3 * sr->max_err, c.no_depth, c.relocalised,
            (unsigned long long)ss.to_disk, (unsigned long long)ss.from_disk,
            (unsigned long long)(ss.chunks_out - sr->last.chunks_out),
            (unsigned long long)(ss.chunks_in - sr->last.chunks_in),
            (unsigned long long)(ss.to_disk - sr->last.to_disk),
            (unsigned long long)(ss.from_disk - sr->last.from_disk),
            (unsigned long long)(ss.disk_bytes - sr->last.disk_bytes), ss.on_disk, ss.cache_bytes / 1048576.0,
            ss.resident, heap_mib(), records_mib(run), load_avg());
    fflush(sr->out);
    fprintf(stderr, "bench_soak: %u/%u frames, %.1f ms median, RSS %.0f MiB, map %.2f MiB, %u lost, "
                    "max error %.1f mm, %llu chunks spilled and %llu reloaded this block, %.0f s\n",
            i + 1, sr->n, bf_stats_percentile(&sr->ms, 50), rss_mib(), st.bytes_total / 1048576.0, c.lost,
            1e3 * sr->max_err, (unsigned long long)(ss.to_disk - sr->last.to_disk),
            (unsigned long long)(ss.from_disk - sr->last.from_disk), bf_time_s() - sr->t_start);
    sr->last = ss;
    bf_stats_free(&sr->ms);
    memset(&sr->ms, 0, sizeof sr->ms);
    sr->max_err = 0;
    return BF_OK;
}

int main(int argc, char **argv)
{
    uint32_t n = 10000, m = 300, block = 250, w = 640, h = 480, zero_n = 0, zero_every = 0;
    double drop = 0, radius = -1, cache_mib = -1;
    uint64_t seed = 1;
    const char *out_path = "soak.tsv", *scene = "room", *trace_path = NULL;
    double step = 0.05;
    uint32_t rooms = 0;
    bool fuse_gt = false;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--frames")) n = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--loop")) m = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--block")) block = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--size")) sscanf(argv[i + 1], "%ux%u", &w, &h);
        else if (!strcmp(argv[i], "--out")) out_path = argv[i + 1];
        else if (!strcmp(argv[i], "--drop")) drop = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--zero")) sscanf(argv[i + 1], "%u/%u", &zero_n, &zero_every);
        else if (!strcmp(argv[i], "--seed")) seed = strtoull(argv[i + 1], NULL, 10);
        else if (!strcmp(argv[i], "--stream-radius")) radius = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--cache-mib")) cache_mib = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--scene")) scene = argv[i + 1];
        else if (!strcmp(argv[i], "--step")) step = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--trace")) trace_path = argv[i + 1];
        else if (!strcmp(argv[i], "--fuse-at-gt")) fuse_gt = atoi(argv[i + 1]) != 0;
        else {
            fprintf(stderr, "usage: bench_soak [--frames N] [--loop M] [--size WxH] [--block B] [--out FILE] "
                            "[--drop P] [--zero N/E] [--seed S] [--stream-radius M] [--cache-mib C] "
                            "[--scene room|rooms:N] [--step M] [--fuse-at-gt 0|1] [--trace FILE]\n");
            return 2;
        }
    }
    if (argc > 1 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        printf("usage: bench_soak [--frames N] [--loop M] [--size WxH] [--block B] [--out FILE.tsv]\n"
               "                  [--drop P] [--zero N/E] [--seed S] [--stream-radius M] [--cache-mib C]\n"
               "                  [--scene room|rooms:N] [--step M]   (rooms: a walk down the row and back,\n"
               "                  M metres a frame; --loop is then the walk's length)\n"
               "                  [--fuse-at-gt 1]   (track every frame, fuse at the true pose)\n"
               "                  [--trace FILE]   (per frame: index, tick, walk or loop frame, state, error mm,\n"
               "                  inliers %%, ms, stream ms)\n");
        return 0;
    }
    int used = 0;
    bool is_rooms = sscanf(scene, "rooms:%u%n", &rooms, &used) == 1 && scene[used] == 0;
    if (!is_rooms && strcmp(scene, "room") != 0) {
        fprintf(stderr, "bench_soak: --scene %s: room or rooms:N\n", scene);
        return 2;
    }
    if (is_rooms && (rooms < 2 || rooms > 64 || !(step >= 0.005 && step <= 0.5))) {
        fprintf(stderr, "bench_soak: --scene rooms:N needs 2 to 64 rooms and --step 0.005 to 0.5 m\n");
        return 2;
    }
    if (is_rooms) m = walk_frames(rooms, step);
    if (m < 2 || block < 1 || w < 16 || h < 16 || !(drop >= 0 && drop < 1) || zero_n > zero_every) {
        fprintf(stderr, "bench_soak: bad option value\n");
        return 2;
    }
    double f_px = 525.0 * w / 640.0;
    bf_intrinsics K = {w, h, f_px, f_px, (w - 1) / 2.0, (h - 1) / 2.0, 5000};
    synth_scene sc = {0};
    synth_renderer *ren = NULL;
    gpu_context *ctx = NULL;
    rgbd_source *src = NULL;
    recon_run run;
    memset(&run, 0, sizeof run);
    size_t np = (size_t)w * h;
    uint16_t *frames = malloc(np * m * sizeof *frames);
    bf_se3 *poses = malloc(m * sizeof *poses);
    bf_status s = !frames || !poses ? BF_NO_MEMORY : is_rooms ? synth_scene_rooms(rooms, &sc) : synth_scene_room(NULL, &sc);
    synth_render_config rc = {.K = K, .noise = SYNTH_NOISE_KINECT1, .seed = 5};
    if (s == BF_OK) s = synth_renderer_create(&sc, &rc, &ren);
    if (is_rooms)
        fprintf(stderr, "bench_soak: rendering a walk of %u frames (%.3f m each) down %u rooms at %ux%u\n", m, step,
                rooms, w, h);
    else
        fprintf(stderr, "bench_soak: rendering a loop of %u frames at %ux%u\n", m, w, h);
    for (uint32_t k = 0; s == BF_OK && k < m; k++) {
        poses[k] = is_rooms ? walk_pose(&sc, k, step) : loop_pose(&sc, k, m);
        s = synth_render(ren, k, &poses[k], frames + np * k, NULL, NULL);
    }
    gpu_config gcfg = {0};
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    recon_run_config cfg = recon_run_config_default();
    /* The synthetic sensor's disparity steps scale with 1/f: below 640
     * wide its depth is coarser than a Kinect's, so the residual gate widens
     * as in tests/tracking. The loop starts at the first frame's true pose. */
    cfg.loop.track.max_residual_m *= (float)(640.0 / w);
    cfg.loop.reloc.max_residual_m *= (float)(640.0 / w); /* a candidate is judged by the same gate */
    cfg.label = "bench_soak";
    if (fuse_gt) cfg.poses = RECON_POSES_TRACK_FUSE_GT;
    if (radius >= 0) cfg.loop.stream.radius_m = (float)radius;
    if (cache_mib >= 0) cfg.loop.stream.cache_bytes = (uint64_t)(cache_mib * 1048576.0);
    uint32_t dropped = 0;
    uint32_t *ticks = soak_ticks(n, drop, seed, &dropped);
    uint16_t *zero = calloc(np, sizeof *zero);
    if (s == BF_OK && (!ticks || !zero)) s = BF_NO_MEMORY;
    fprintf(stderr, "bench_soak: %u frames, %u ticks dropped, %u zero-depth frames every %u\n", n, dropped, zero_n,
            zero_every);
    soak_frames sf = {poses, frames, zero, m, w, h, ticks, zero_n, zero_every};
    if (s == BF_OK) s = capture_source_from_fn(&K, n, true, soak_frame, &sf, &src);
    soak_report sr = {.n = n, .block = block, .t_start = bf_time_s(), .sf = &sf};
    if (s == BF_OK && trace_path && !(sr.trace = fopen(trace_path, "w")))
        s = bf_fail(BF_IO, "%s: cannot create", trace_path);
    if (s == BF_OK && !(sr.out = fopen(out_path, "w"))) s = bf_fail(BF_IO, "%s: cannot create", out_path);
    if (sr.out)
        fprintf(sr.out, "frames\tms_median\tms_p95\trss_mib\tmap_mib\tbricks\ttracked\tlost\tmax_error_mm\tno_depth\t"
                        "relocalised\tto_disk\tfrom_disk\tchunks_out\tchunks_in\tspilled\treloaded\tspill_bytes\t"
                        "on_disk\tcache_mib\tresident_chunks\theap_mib\trecords_mib\tload\n");
    if (s == BF_OK) s = recon_run_sequence(ctx, src, &cfg, soak_on_frame, &sr, &run);
    if (s != BF_OK) fprintf(stderr, "bench_soak: %s: %s\n", bf_status_name(s), bf_last_error());
    stream_stats ss = run.loop ? recon_stream_stats(run.loop) : (stream_stats){0};
    fprintf(stderr, "bench_soak: stream: %llu chunks out and %llu in, %llu to disk (%.1f MiB) and %llu back, "
                    "cache at most %.2f MiB, checks %.1f ms at most\n",
            (unsigned long long)ss.chunks_out, (unsigned long long)ss.chunks_in, (unsigned long long)ss.to_disk,
            ss.disk_bytes / 1048576.0, (unsigned long long)ss.from_disk, ss.cache_bytes_max / 1048576.0, ss.ms_max);
    bf_stats_free(&sr.ms);
    if (sr.out) fclose(sr.out);
    if (sr.trace) fclose(sr.trace);
    recon_run_free(&run);
    rgbd_source_close(src);
    gpu_context_destroy(ctx);
    synth_renderer_destroy(ren);
    synth_scene_free(&sc);
    free(frames);
    free(poses);
    free(ticks);
    free(zero);
    return s == BF_OK ? 0 : 1;
}
