/* bitfuse calibrate: the colour camera's intrinsics and distortion and,
 * with the depth (IR) camera's views of the same board, its intrinsics and
 * T_colour_depth, from checkerboard images (calib/, Zhang 2000 through
 * OpenCV's calib3d); written as calib.json for --calibration. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "calib/calib.h"
#include "replay/replay.h"

static const char calibrate_usage[] =
    "usage: bitfuse calibrate --board COLSxROWS --square M [--depth IMAGES...] IMAGES... --out calib.json\n"
    "                         [--radial 2|3] [--json]\n"
    "\n"
    "Finds the checkerboard's inner corners in each colour image (IMAGES, PNG or JPEG) and\n"
    "calibrates the colour camera: fx, fy, cx, cy and the distortion k1 k2 p1 p2 k3\n"
    "(Zhang 2000, OpenCV's calib3d). With --depth, the IR images of the depth camera, one\n"
    "per colour image and taken at the same moment, calibrate the depth camera too and the\n"
    "transform T_colour_depth between the two (the views both found). --depth takes the\n"
    "arguments after it up to the next option or '--': put the colour images before it or\n"
    "after '--'. Reports each image (board found or not) and the reprojection errors, and\n"
    "writes the calibration to --out atomically (docs/formats.md, calib.json).\n"
    "At least 3 views must show the whole board; cols + rows odd (9x6) tells the board's\n"
    "ends apart, which the pairing of depth and colour views needs.\n";

static const char calibrate_epilog[] =
    "exit codes: 0 ok, 1 the calibration failed (numerics), 2 usage, 3 an unreadable image,\n"
    "images of different sizes or too few views with the board found (the files are named),\n"
    "5 calib.json could not be written (disk full, I/O error; no half file is left)\n"
    "See docs/calibration.md.\n";

static const char *check_board(const char *name, const char *v)
{
    static char msg[512];
    calib_board b;
    if (calib_parse_board(v, &b) == BF_OK) return NULL;
    snprintf(msg, sizeof msg, "%s: %s", name, bf_last_error());
    return msg;
}

/* One camera's images and what was found in them. */
typedef struct camera_images {
    const char *name;          /* "colour", "depth" */
    const char **paths;
    uint32_t n;
    uint32_t width, height;    /* of the first image; the others must match */
    double *corners;           /* n * cols * rows * 2 */
    bool *is_found;
    bool *is_used;             /* found and not a repeat of an earlier view: what the fit takes */
    uint32_t n_found;
} camera_images;

/* Reads each image into grey (ITU-R BT.601 luma, as OpenCV's cvtColor)
 * and looks for the board; a line per image on stderr. */
static bf_status find_all(const calib_board *b, camera_images *c, bool is_quiet)
{
    size_t nc = (size_t)b->cols * b->rows;
    c->corners = calloc(c->n * nc * 2 + 1, sizeof *c->corners);
    c->is_found = calloc(c->n + 1, sizeof *c->is_found);
    c->is_used = calloc(c->n + 1, sizeof *c->is_used);
    if (!c->corners || !c->is_found || !c->is_used)
        return bf_fail(BF_NO_MEMORY, "calibrate: corners of %u images", c->n);
    for (uint32_t k = 0; k < c->n; k++) {
        uint8_t *rgb = NULL;
        uint32_t w, h;
        bf_status s = replay_image_read_rgb8(c->paths[k], &rgb, &w, &h);
        if (s != BF_OK) return s;
        if (k == 0) c->width = w, c->height = h;
        if (w != c->width || h != c->height) {
            free(rgb);
            return bf_fail(BF_FORMAT, "%s: %ux%u, but the first %s image (%s) is %ux%u", c->paths[k], w, h, c->name,
                           c->paths[0], c->width, c->height);
        }
        uint8_t *grey = (uint8_t *)rgb; /* in place: pixel i's grey lands before its RGB is read */
        for (size_t i = 0; i < (size_t)w * h; i++)
            grey[i] = (uint8_t)((299 * rgb[3 * i] + 587 * rgb[3 * i + 1] + 114 * rgb[3 * i + 2] + 500) / 1000);
        s = calib_find_corners(b, grey, w, h, &c->is_found[k], c->corners + 2 * nc * k);
        free(rgb);
        if (s != BF_OK) return s;
        c->n_found += c->is_found[k];
        if (!is_quiet)
            fprintf(stderr, "calibrate: %s %u/%u %s: %s\n", c->name, k + 1, c->n, c->paths[k],
                    c->is_found[k] ? "board found" : "no board found");
    }
    return BF_OK;
}

/* A view whose corners all lie within half a pixel of an earlier one's (the
 * same image given twice, a camera left still) adds no constraint: it is
 * left out of the fit (which would weigh that view twice) and the count of
 * views, warned about; too few distinct views are too few views
 * (calibrateCamera fits the noise of repeated ones). */
static bf_status distinct_views(const calib_board *b, camera_images *c)
{
    size_t nc = (size_t)b->cols * b->rows;
    uint32_t n_same = 0;
    for (uint32_t k = 0; k < c->n; k++) c->is_used[k] = c->is_found[k];
    for (uint32_t k = 1; k < c->n; k++) {
        if (!c->is_found[k]) continue;
        for (uint32_t j = 0; j < k; j++) {
            if (!c->is_found[j]) continue;
            double worst = 0;
            for (size_t i = 0; i < 2 * nc; i++)
                worst = fmax(worst, fabs(c->corners[k * nc * 2 + i] - c->corners[j * nc * 2 + i]));
            if (worst < 0.5) {
                bf_warn("calibrate: %s %s shows the board where %s does (every corner within 0.5 px): it adds "
                        "nothing and is left out", c->name, c->paths[k], c->paths[j]);
                c->is_used[k] = false; /* it would weigh that view twice */
                n_same++;
                break;
            }
        }
    }
    if (c->n_found - n_same < CALIB_MIN_VIEWS)
        return bf_fail(BF_FORMAT, "%u %s views show the board at %u different places (at least %d needed): move the "
                       "board or the camera between images", c->n_found, c->name, c->n_found - n_same, CALIB_MIN_VIEWS);
    return BF_OK;
}

/* Too few views: the message names the images without the board. */
static bf_status too_few(const camera_images *c)
{
    char list[2048] = "";
    uint32_t shown = 0;
    for (uint32_t k = 0; k < c->n; k++) {
        if (c->is_found[k]) continue;
        size_t used = strlen(list);
        if (shown == 8) {
            snprintf(list + used, sizeof list - used, ", ...");
            break;
        }
        snprintf(list + used, sizeof list - used, "%s%s", shown ? ", " : "", c->paths[k]);
        shown++;
    }
    if (!shown) /* found in every image, but too few were given */
        return bf_fail(BF_FORMAT, "the board was found in all %u %s images, and at least %d are needed", c->n, c->name,
                       CALIB_MIN_VIEWS);
    return bf_fail(BF_FORMAT, "the board was found in %u of %u %s images (at least %d needed); not in: %s", c->n_found,
                   c->n, c->name, CALIB_MIN_VIEWS, list);
}

static void print_camera(const char *name, const calib_camera *c)
{
    printf("  %-7s %ux%u  fx %.3f  fy %.3f  cx %.3f  cy %.3f  RMS %.3f px\n", name, c->width, c->height, c->fx_px,
           c->fy_px, c->cx_px, c->cy_px, c->rms_px);
    printf("          distortion k1 %.5f k2 %.5f p1 %.6f p2 %.6f k3 %.5f\n", c->dist[0], c->dist[1], c->dist[2],
           c->dist[3], c->dist[4]);
    printf("          the boards reached %.0f%% of the way to the image's corners", 100 * c->coverage);
    if (c->coverage < 1) printf("; beyond, two and three radial terms differ by up to %.3g px", c->extrapolation_px);
    printf("\n");
}

static void print_summary(const calib_result *r, const char *out)
{
    printf("bitfuse calibrate: %u views -> %s\n", r->n_views, out);
    print_camera("colour", &r->colour);
    if (r->has_depth) {
        print_camera("depth", &r->depth);
        const bf_se3 *T = &r->T_colour_depth;
        printf("  T_colour_depth  t (%.2f, %.2f, %.2f) mm, rotation %.3f deg; stereo RMS %.3f px\n", 1e3 * T->t.x,
               1e3 * T->t.y, 1e3 * T->t.z, bf_se3_angle(T) * 180 / M_PI, r->rms_px);
    }
}

/* The calibration and each image's outcome, for --json. */
static bf_status print_json(const calib_result *r, const camera_images *cams, int n_cams, const char *out)
{
    char *text;
    bf_status s = calib_to_text(r, &text);
    if (s != BF_OK) return s;
    cJSON *root = cJSON_CreateObject();
    /* Raw: cJSON would print the numbers again with 15 digits. */
    cJSON_AddItemToObject(root, "calibration", cJSON_CreateRaw(text));
    free(text);
    cJSON_AddStringToObject(root, "out", out);
    cJSON *images = cJSON_AddArrayToObject(root, "images");
    for (int i = 0; i < n_cams; i++)
        for (uint32_t k = 0; k < cams[i].n; k++) {
            cJSON *o = cJSON_CreateObject();
            cJSON_AddStringToObject(o, "camera", cams[i].name);
            cJSON_AddStringToObject(o, "path", cams[i].paths[k]);
            cJSON_AddBoolToObject(o, "found", cams[i].is_found[k]);
            cJSON_AddBoolToObject(o, "used", cams[i].is_used[k]); /* found and not a repeat of an earlier view */
            cJSON_AddItemToArray(images, o);
        }
    return app_json_print(root);
}

int cmd_calibrate(int argc, char **argv)
{
    const char *cmd = "calibrate";
    const char *board_text = NULL, *out = NULL;
    double square_m = 0;
    bool json = false;
    calib_config cfg = calib_config_default();
    int rc = APP_EXIT_OK;
    /* --depth takes a list, which the option table cannot: it is taken out
     * of the command line first, up to the next option or "--". */
    char **rest = calloc((size_t)argc + 1, sizeof *rest);
    const char **depth = calloc((size_t)argc + 1, sizeof *depth), **colour = calloc((size_t)argc + 1, sizeof *colour);
    camera_images cams[2] = {{.name = "colour", .paths = colour}, {.name = "depth", .paths = depth}};
    if (!rest || !depth || !colour) {
        rc = app_fail(cmd, bf_fail(BF_NO_MEMORY, "command line"));
        goto done;
    }
    int n_rest = 0;
    bool has_depth = false;
    for (int i = 0; i < argc; i++) {
        if (i > 0 && !strcmp(argv[i], "--depth")) {
            has_depth = true;
            while (i + 1 < argc && argv[i + 1][0] != '-') depth[cams[1].n++] = argv[++i];
            if (i + 1 < argc && !strcmp(argv[i + 1], "--")) i++;
        } else if (i > 0 && !strncmp(argv[i], "--depth=", 8)) {
            has_depth = true;
            depth[cams[1].n++] = argv[i] + 8;
        } else if (i > 0 && !strcmp(argv[i], "--")) {
            continue;
        } else {
            rest[n_rest++] = argv[i];
        }
    }
    const app_option own[] = {
        APP_OPT("--board", APP_OPT_STRING, &board_text, "COLSxROWS", "inner corners of the checkerboard (e.g. 9x6)",
                .required = true, .check = check_board),
        APP_OPT("--square", APP_OPT_DOUBLE, &square_m, "M", "edge of a square in metres", .min_open = true, .max = 10,
                .required = true, .no_default = true),
        APP_OPT("--out", APP_OPT_STRING, &out, "FILE", "the calibration file to write (calib.json)", .required = true),
        APP_OPT("--radial", APP_OPT_U32, &cfg.radial_terms, "N",
                "radial distortion terms: 3 (k1 k2 k3) or 2 (k3 held at 0: for a mild lens whose boards stay off "
                "the image's corners, where a third term can swing far out)",
                .min = 2, .max = 3),
        APP_OPT("--json", APP_OPT_FLAG, &json, NULL,
                "print the calibration and each image's outcome as JSON instead of the summary"),
        APP_OPT_END,
    };
    /* Shown in the help only: --depth is taken out above. */
    const app_option shown[] = {
        APP_OPT("--depth", APP_OPT_STRING, &out, "IMAGES...",
                "the depth camera's IR images of the same views, in the same order as IMAGES", .no_default = true),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, NULL}, *help_tables[] = {own, shown, NULL};
    app_command_spec spec = {.name = cmd, .usage = calibrate_usage, .tables = tables, .positional = colour,
                             .min_positional = 1, .max_positional = argc, .positional_missing = "no colour images given",
                             .epilog = calibrate_epilog};
    for (int i = 1; i < n_rest; i++)
        if (!strcmp(rest[i], "-h") || !strcmp(rest[i], "--help")) {
            spec.tables = help_tables;
            app_options_help(stdout, &spec);
            goto done;
        }
    if ((rc = app_options_parse(&spec, n_rest, rest)) != 0) {
        rc = rc < 0 ? APP_EXIT_OK : rc;
        goto done;
    }
    while (cams[0].n < (uint32_t)argc && colour[cams[0].n]) cams[0].n++;
    if (has_depth && cams[1].n == 0) {
        rc = app_usage_error(cmd, "--depth names no images");
        goto done;
    }
    if (has_depth && cams[1].n != cams[0].n) {
        rc = app_usage_error(cmd, "%u depth images for %u colour images: they pair by order, one each", cams[1].n,
                             cams[0].n);
        goto done;
    }
    /* Not over an image it reads, nor over one --out names by mistake
     * (--out written before the shell's glob takes the first image). */
    for (int i = 0; i < (has_depth ? 2 : 1) && !rc; i++)
        for (uint32_t k = 0; k < cams[i].n && !rc; k++) rc = app_check_not_input(cmd, "--out", out, cams[i].paths[k]);
    if (!rc) rc = app_check_json_out(cmd, "--out", out);
    if (rc) goto done;
    calib_board board;
    calib_parse_board(board_text, &board); /* checked above */
    board.square_m = square_m;
    int n_cams = has_depth ? 2 : 1;
    bf_status s = BF_OK;
    for (int i = 0; i < n_cams && s == BF_OK; i++) s = find_all(&board, &cams[i], false);
    for (int i = 0; i < n_cams && s == BF_OK; i++)
        if (cams[i].n_found < CALIB_MIN_VIEWS) s = too_few(&cams[i]);
    for (int i = 0; i < n_cams && s == BF_OK; i++) s = distinct_views(&board, &cams[i]);
    calib_result r;
    if (s == BF_OK) {
        calib_views cv = {.n_views = cams[0].n, .width = cams[0].width, .height = cams[0].height,
                          .corners_px = cams[0].corners, .is_found = cams[0].is_used};
        calib_views dv = {.n_views = cams[1].n, .width = cams[1].width, .height = cams[1].height,
                          .corners_px = cams[1].corners, .is_found = cams[1].is_used};
        s = calib_estimate(&board, &cfg, &cv, has_depth ? &dv : NULL, &r);
    }
    /* The pair fitting far worse than each camera alone: views that do not
     * pair up (--depth in another order than IMAGES), or a camera moved. */
    if (s == BF_OK && has_depth && r.rms_px > 1.0 && r.rms_px > 5 * fmax(r.colour.rms_px, r.depth.rms_px))
        bf_warn("calibrate: the pair's reprojection RMS %.2f px is %.0f times the cameras' own (%.2f, %.2f px): are "
                "the --depth images in the same order as the colour ones, and did the rig hold still in each view?",
                r.rms_px, r.rms_px / fmax(r.colour.rms_px, r.depth.rms_px), r.colour.rms_px, r.depth.rms_px);
    /* Frames are undistorted to their corners (--calibration): a lens that
     * is a guess there is worth a word. */
    for (int i = 0; i < n_cams && s == BF_OK; i++) {
        const calib_camera *c = i ? &r.depth : &r.colour;
        if (c->extrapolation_px > CALIB_EXTRAPOLATION_WARN_PX)
            bf_warn("calibrate: %s: the boards reached %.0f%% of the way to the image's corners, and beyond them the "
                    "lens is a guess: fits with two and three radial terms, alike within the boards, differ by %.3g px "
                    "at the image's edge; add views with the board near the image's corners and edges",
                    cams[i].name, 100 * c->coverage, c->extrapolation_px);
    }
    if (s == BF_OK) s = calib_write(out, &r);
    if (s == BF_OK) {
        if (json) s = print_json(&r, cams, n_cams, out);
        else print_summary(&r, out);
    }
    if (s != BF_OK) rc = app_fail(cmd, s);
done:
    for (int i = 0; i < 2; i++) {
        free(cams[i].corners);
        free(cams[i].is_found);
        free(cams[i].is_used);
    }
    free(rest);
    free(depth);
    free(colour);
    return rc;
}
