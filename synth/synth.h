/* synth: synthetic RGB-D sequences with ground truth (`bitfuse synth`): a
 * CPU ray tracer renders depth and colour of a scene along a trajectory,
 * with a Kinect v1 noise model, into a TUM folder. Scenes (room.c), sensor
 * model (noise.c), renderer (raytrace.c), sequences (synth.c). Depends on
 * core, mesh, replay (the TUM-folder writer and trajectory files) and calib
 * (the camera model of the checkerboard views, board.c).
 * See docs/synth.md. */
#ifndef BF_SYNTH_H
#define BF_SYNTH_H

#include "calib/calib.h"
#include "core/core.h"
#include "mesh/mesh.h"

typedef enum synth_noise {
    SYNTH_NOISE_NONE,    /* ideal sensor: exact depth, rounded to 1/depth_scale */
    SYNTH_NOISE_KINECT1, /* Kinect v1 (Nguyen, Izadi, Lovell 2012): synth_kinect1_* */
} synth_noise;

/* Procedural materials: the albedo is a function of the world point, so no
 * texture coordinates are needed. */
typedef enum synth_material {
    SYNTH_MAT_PLAIN,   /* flat grey (meshes given with --scene MESH.ply) */
    SYNTH_MAT_FLOOR,   /* wooden planks */
    SYNTH_MAT_WALL,    /* painted plaster with blotches and posters */
    SYNTH_MAT_CEILING, /* off-white tiles */
    SYNTH_MAT_TABLE,   /* dark wood */
    SYNTH_MAT_BOX,     /* two-tone checker, colour by variant */
    SYNTH_MAT_OBJECT,  /* mottled solid colour, colour by variant */
    SYNTH_MAT_COUNT
} synth_material;

/* A scene to render: one mesh in world coordinates (metres) plus a material
 * and a variant (which colour) per triangle. Owns all arrays. */
typedef struct synth_scene {
    mesh_data mesh;          /* world frame, metres; mesh.normal holds vertex normals */
    uint8_t *tri_material;   /* synth_material, one per triangle */
    uint8_t *tri_variant;    /* one per triangle */
    bf_vec3 light_w;         /* point light for Lambert shading */
    bf_se3 T_wc_view;        /* where the first camera of a trajectory is placed */
    char desc[512];          /* what went in, for the log and stats.json */
} synth_scene;

/* The procedural room (room.c): 4 x 3.5 x 2.5 m, z up, floor at z = 0, with a
 * table, boxes and, when data_dir/meshes holds them, the bunny, armadillo and
 * dragon scaled to 15-25 cm standing on the table. data_dir may be NULL or
 * lack the meshes: the room is built without them (logged). */
bf_status synth_scene_room(const char *data_dir, synth_scene *out);
/* A row of n rooms (each 4 x 3.5 x 2.5 m, along +x from x = -2) joined by
 * doorways, with tables and boxes placed differently in each: a scene tens
 * of metres long for streaming. The view stands in the first room looking
 * along +x. BF_INVALID_ARG unless 1 <= n <= 64. */
bf_status synth_scene_rooms(uint32_t n, synth_scene *out);
/* A scene of one PLY mesh, vertices multiplied by scale (metres after
 * scaling). The view looks at the mesh's box centre along -z from where its
 * bounding sphere fills the image (fx = 525, 480 rows), y up. */
bf_status synth_scene_from_ply(const char *path, double scale, synth_scene *out);
/* Takes ownership of mesh (left zeroed) as a scene with material PLAIN and
 * the given view; for tests and custom scenes. Computes vertex normals. */
bf_status synth_scene_from_mesh(mesh_data *mesh, const bf_se3 *T_wc_view, synth_scene *out);
void synth_scene_free(synth_scene *s); /* NULL is a no-op */
/* The colour the renderer gives point p_w of triangle tri (barycentrics u,
 * v of its vertices 1 and 2) seen along view_dir: procedural albedo times
 * ambient + Lambert from the scene's light, channels in [0, 1] before the
 * sensor's noise. View-independent but for the side: the normal faces the
 * viewer. What the colour checks compare a fused map's colour with. */
void synth_scene_shade(const synth_scene *sc, uint32_t tri, double u, double v, bf_vec3 p_w, bf_vec3 view_dir,
                       double rgb[3]);
/* Camera-to-world pose of a camera at eye looking at target (camera x
 * right, y down, z forward; up_w is the world's up). */
bf_se3 synth_look_at(bf_vec3 eye_w, bf_vec3 target_w, bf_vec3 up_w);

/* Kinect v1 sensor model (noise.c). z in metres along the optical axis,
 * theta the angle between the viewing ray and the surface normal. */
#define SYNTH_KINECT1_BASELINE_M 0.075  /* projector - IR camera */
#define SYNTH_KINECT1_DISP_STEP_PX 0.125 /* disparity in 1/8 pixel steps */
#define SYNTH_KINECT1_Z_MIN_M 0.5
#define SYNTH_KINECT1_Z_MAX_M 4.5
#define SYNTH_KINECT1_MAX_THETA_DEG 80.0 /* no depth at more grazing angles */
/* Axial (depth) standard deviation of Nguyen et al. 2012, eq. (2) and (3):
 * 0.0012 + 0.0019 (z - 0.4)^2 [+ 0.0001 / sqrt(z) theta^2 / (pi/2 - theta)^2
 * beyond 60 degrees]. This is the total, quantisation included. */
double synth_kinect1_axial_sigma(double z_m, double theta_rad);
/* Lateral standard deviation in pixels: 0.8 + 0.035 theta / (pi/2 - theta). */
double synth_kinect1_lateral_sigma_px(double theta_rad);
/* Depth step of the disparity quantisation at z: z^2 step / (baseline fx). */
double synth_kinect1_depth_step(double z_m, double fx_px);
/* The Gaussian part: sqrt(axial^2 - step^2 / 12), so that the Gaussian plus
 * the (uniform) quantisation error have the model's variance. */
double synth_kinect1_gauss_sigma(double z_m, double theta_rad, double fx_px);
/* Depth after quantising its disparity on the grid (k + offset) * step,
 * offset in [0, 1); z <= 0 gives 0. */
double synth_kinect1_quantize(double z_m, double fx_px, double offset);

/* The renderer: one per image size and scene, reused for every frame. */
typedef struct synth_render_config {
    bf_intrinsics K;   /* size, pinhole (ray through the pixel centre), depth_scale */
    synth_noise noise;
    uint64_t seed;
} synth_render_config;

typedef struct synth_render_stats {
    uint32_t n_hit;    /* pixels whose ray hit the scene */
    uint32_t n_valid;  /* pixels with depth after the sensor model */
    double seconds;
} synth_render_stats;

typedef struct synth_renderer synth_renderer;
/* Builds the scene's BVH and the image buffers. The scene is borrowed and
 * must outlive the renderer. */
bf_status synth_renderer_create(const synth_scene *scene, const synth_render_config *cfg, synth_renderer **out);
void synth_renderer_destroy(synth_renderer *r); /* NULL is a no-op */
/* Renders the frame numbered frame (it keys the noise) at camera pose T_wc
 * into depth (width*height raw units, 0 = none) and rgb (width*height*3,
 * may be NULL). Multi-threaded; the result depends only on the scene, the
 * config, frame and T_wc. st may be NULL. */
bf_status synth_render(synth_renderer *r, uint32_t frame, const bf_se3 *T_wc, uint16_t *depth, uint8_t *rgb,
                      synth_render_stats *st);
/* The noise-free world point seen at pixel (u, v) in the last synth_render,
 * true only if that pixel got valid depth. */
bool synth_render_clean_point(const synth_renderer *r, uint32_t u, uint32_t v, bf_vec3 *p_w);

/* A whole sequence (synth.c): what `bitfuse synth` runs. */
typedef struct synth_config {
    const char *scene;      /* "room", "rooms:N" (a row of N rooms) or a PLY path */
    const char *data_dir;   /* shared data for the room's meshes; NULL = none */
    double mesh_scale;      /* for a PLY scene; 0 = 1 */
    const char *traj_path;  /* TUM trajectory the camera follows */
    uint32_t n_frames;      /* frames to render (fewer if the trajectory ends) */
    double rate_hz;         /* 0 = 30 */
    synth_noise noise;
    uint64_t seed;
    bf_intrinsics K;        /* size 0 = 640x480; fx 0 = 525 w / 640 for fx and fy, (w-1)/2, (h-1)/2;
                               depth_scale 0 = 5000 */
    const char *out_dir;
    double seen_cell_m;     /* seen.ply grid; 0 = 0.005 */
    const char *version;    /* the program's version, echoed in stats.json; NULL: left out */
} synth_config;

typedef struct synth_result {
    uint32_t n_frames;      /* written */
    double mean_frame_s, median_frame_s; /* render time per frame */
    double total_s;         /* wall time of the whole run (scene, BVH, PNGs, ...) */
    double valid_share;     /* valid depth pixels / all pixels */
    bf_se3 T_world_traj;    /* placement: rendered pose = T_world_traj * trajectory pose */
    uint32_t n_seen;        /* points in seen.ply */
    uint32_t n_scene_tris;
} synth_result;

/* Renders cfg->n_frames frames at cfg->rate_hz from the trajectory's first
 * timestamp, poses interpolated (bf_traj_interpolate) and placed by
 * T_world_traj = scene.T_wc_view * inv(first pose), and writes out_dir:
 * rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt (rendered poses),
 * camera.txt, scene.ply, seen.ply, stats.json. A trajectory shorter than
 * requested stops early with a warning; no frame at all is BF_INVALID_ARG. */
bf_status synth_run(const synth_config *cfg, synth_result *out);

/* ------------------------------------------------------------ checkerboards (board.c)
 * Views of a planar checkerboard for `bitfuse calibrate`, seen by a colour
 * camera and by the depth (IR) camera beside it, at known intrinsics,
 * distortion and T_colour_depth: the calibration's ground truth. */

typedef struct synth_board_config {
    calib_board board;        /* inner corners and square size */
    uint32_t n_views;
    calib_camera colour;      /* size, pinhole and distortion of the colour camera */
    calib_camera depth;       /* the same of the IR camera */
    bf_se3 T_colour_depth;    /* p_colour = T_colour_depth * p_depth */
    uint32_t supersample;     /* samples per pixel side at the board's edges (box filter); 0 = 8 */
    double noise_levels;      /* sensor noise, standard deviation in 8-bit grey levels */
    uint64_t seed;            /* keys the poses and the noise */
    const char *out_dir;
} synth_board_config;

/* 9 x 6 corners of 4 cm, 15 views; colour 640x480 at 525 px without
 * distortion, IR 640x480 at 580 px; T_colour_depth 25 mm along -x (the
 * colour camera sits to the IR camera's right) turned 0.5 degrees; 8 x 8
 * samples at edges, noise 1 level, seed 1. out_dir is left NULL. */
synth_board_config synth_board_config_default(void);

typedef struct synth_board_result {
    uint32_t n_views;
    double seconds;
} synth_board_result;

/* Board-to-camera pose of view k of n (colour camera): the board's centre
 * 0.55-1.1 m ahead, tilted 15-45 degrees about an axis that turns with k
 * (Zhang's method needs planes in different orientations), turned up to
 * 20 degrees in its plane, placed so that it and a one-square white margin
 * lie inside both cameras' images. Draws keyed by seed and k;
 * BF_INVALID_ARG when 200 draws do not fit (a board too large for the
 * cameras). */
bf_status synth_board_pose(const synth_board_config *cfg, uint32_t k, bf_se3 *T_colour_board);
/* Renders the board seen by camera c at T_cb (board to camera) into grey
 * (c->width * c->height, 8-bit): black and white squares (square (0, 0),
 * diagonally outside corner (0, 0), is black), a white margin of one square
 * around them, a smooth grey background; pixels that an edge crosses are
 * the mean of supersample^2 samples, so the image is the box-filtered
 * scene and corners are found to a small fraction of a pixel. Noise is
 * keyed by (seed, stream, pixel). */
bf_status synth_board_render(const synth_board_config *cfg, const calib_camera *c, const bf_se3 *T_cb,
                             uint32_t stream, uint8_t *grey);
/* Writes out_dir/colour/NNN.png and out_dir/ir/NNN.png (8-bit, grey in
 * RGB), truth.json (the calibration that made them, calib.json's format)
 * and board_poses.txt (TUM: index, colour camera to board). */
bf_status synth_board_run(const synth_board_config *cfg, synth_board_result *out);

#endif
