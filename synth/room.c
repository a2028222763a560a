/* eval: scenes for the synthetic sequences: the procedural room, a scene of
 * one PLY mesh, and their procedural textures.
 *
 * The room (world frame: z up, floor at z = 0, metres):
 *   walls x in [-2, 2], y in [-1.75, 1.75], ceiling at 2.5;
 *   a table 1.2 x 0.8 m, top at 0.76 m, centred at (0.6, 0);
 *   two boxes on the table, two on the floor;
 *   the shared bunny, armadillo and dragon (when present) on the table.
 * Every large face is cut into cells of at most SYNTH_ROOM_CELL_M so that no
 * triangle's box spans the room: the BVH then separates near and far
 * surfaces (one wall as two triangles would overlap every node it meets).
 * The default view stands at (-0.9, -0.7, 1.45) looking at the table,
 * 1.75 m away, the way a person holding a sensor would. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "synth_int.h"

#define SYNTH_ROOM_CELL_M 0.25

/* ------------------------------------------------------------ textures */

/* One mix of a linear combination: enough to decorrelate lattice points
 * for a texture, and the texture is a tenth of the render time. */
static double hash01(int64_t a, int64_t b, int64_t c, uint64_t salt)
{
    return synth__u01(synth__mix64((uint64_t)a * 0x9e3779b97f4a7c15ull + (uint64_t)b * 0xc2b2ae3d27d4eb4full +
                                 (uint64_t)c * 0x165667b19e3779f9ull + salt * 0x27d4eb2f165667c5ull));
}

/* Smooth value noise in [0, 1] (trilinear over a hashed lattice). */
static double vnoise(bf_vec3 p, uint64_t salt)
{
    double fx = floor(p.x), fy = floor(p.y), fz = floor(p.z);
    int64_t ix = (int64_t)fx, iy = (int64_t)fy, iz = (int64_t)fz;
    double tx = p.x - fx, ty = p.y - fy, tz = p.z - fz;
    tx = tx * tx * (3 - 2 * tx);
    ty = ty * ty * (3 - 2 * ty);
    tz = tz * tz * (3 - 2 * tz);
    double v = 0;
    for (int k = 0; k < 8; k++) {
        int dx = k & 1, dy = (k >> 1) & 1, dz = k >> 2;
        double w = (dx ? tx : 1 - tx) * (dy ? ty : 1 - ty) * (dz ? tz : 1 - tz);
        v += w * hash01(ix + dx, iy + dy, iz + dz, salt);
    }
    return v;
}

static const double palette[8][3] = {
    {0.80, 0.20, 0.15}, {0.20, 0.45, 0.80}, {0.90, 0.75, 0.20}, {0.25, 0.65, 0.30},
    {0.60, 0.30, 0.70}, {0.95, 0.55, 0.20}, {0.20, 0.70, 0.75}, {0.85, 0.85, 0.80},
};

static void set_rgb(double rgb[3], const double c[3], double s)
{
    for (int k = 0; k < 3; k++) rgb[k] = c[k] * s;
}

void synth__albedo(uint8_t material, uint8_t variant, bf_vec3 p, double rgb[3])
{
    switch (material) {
    case SYNTH_MAT_FLOOR: {
        /* Planks 14 cm wide along x, 1.2 m long, staggered; grain; dark gaps. */
        double w = 0.14, len = 1.2;
        double row = floor(p.y / w);
        double seg = floor((p.x + row * 0.37) / len);
        double fy = p.y / w - row, fx = (p.x + row * 0.37) / len - seg;
        double tone = 0.7 + 0.45 * hash01((int64_t)row, (int64_t)seg, 0, 11);
        double grain = 0.85 + 0.15 * sin(p.x * 55.0 + 6.0 * vnoise(bf_v3_scale(p, 7.0), 12));
        double gap = (fy < 0.03 || fy > 0.97 || fx < 0.004) ? 0.35 : 1.0;
        const double wood[3] = {0.55, 0.37, 0.21};
        set_rgb(rgb, wood, tone * grain * gap);
        break;
    }
    case SYNTH_MAT_WALL: {
        /* Plaster with soft blotches; posters in some cells of a 0.9 m grid,
         * in the row at 0.9-1.8 m.
         * variant 0: wall at constant x (runs along y); 1: constant y. */
        double h = variant == 0 ? p.y : p.x, z = p.z;
        const double paint[3] = {0.84, 0.81, 0.74};
        set_rgb(rgb, paint, 0.8 + 0.2 * vnoise(bf_v3_scale(p, 2.5), 21) + 0.05 * vnoise(bf_v3_scale(p, 30), 22));
        double cell = 0.9, ch = floor(h / cell), cz = floor(z / cell);
        double fh = h / cell - ch, fz = z / cell - cz;
        uint64_t salt = 23 + variant;
        if (cz == 1 && hash01((int64_t)ch, (int64_t)cz, variant, salt) < 0.6 && fh > 0.15 && fh < 0.85 &&
            fz > 0.1 && fz < 0.9) {
            int c0 = (int)(hash01((int64_t)ch, (int64_t)cz, 1, salt) * 8), c1 = (c0 + 3) % 8;
            int style = (int)(hash01((int64_t)ch, (int64_t)cz, 2, salt) * 3);
            bool on;
            if (style == 0)
                on = ((int)floor(fh * 10) + (int)floor(fz * 10)) & 1; /* checker */
            else if (style == 1)
                on = sin((fh + fz) * 40.0) > 0; /* diagonal stripes */
            else
                on = hypot(fh - 0.5, fz - 0.5) < 0.25 + 0.08 * vnoise(bf_v3(fh * 8, fz * 8, ch), 24); /* blob */
            set_rgb(rgb, palette[on ? c0 : c1], 1.0);
            if (fh < 0.17 || fh > 0.83 || fz < 0.12 || fz > 0.88) set_rgb(rgb, palette[7], 0.25); /* frame */
        }
        break;
    }
    case SYNTH_MAT_CEILING: {
        double fx = p.x / 0.6 - floor(p.x / 0.6), fy = p.y / 0.6 - floor(p.y / 0.6);
        const double white[3] = {0.92, 0.92, 0.90};
        set_rgb(rgb, white, (fx < 0.02 || fy < 0.02) ? 0.6 : 0.92 + 0.08 * vnoise(bf_v3_scale(p, 20), 31));
        break;
    }
    case SYNTH_MAT_TABLE: {
        const double wood[3] = {0.40, 0.25, 0.14};
        double grain = 0.8 + 0.2 * sin(p.x * 80.0 + 8.0 * vnoise(bf_v3_scale(p, 10.0), 41));
        set_rgb(rgb, wood, grain * (0.9 + 0.2 * vnoise(bf_v3_scale(p, 3.0), 42)));
        break;
    }
    case SYNTH_MAT_BOX: {
        double s = 0.04;
        int parity = ((int)floor(p.x / s) + (int)floor(p.y / s) + (int)floor(p.z / s)) & 1;
        set_rgb(rgb, palette[(variant + (parity ? 4 : 0)) % 8], parity ? 0.9 : 1.0);
        break;
    }
    case SYNTH_MAT_OBJECT:
        set_rgb(rgb, palette[variant % 8], 0.7 + 0.3 * vnoise(bf_v3_scale(p, 60.0), 51));
        break;
    default: {
        const double grey[3] = {0.7, 0.7, 0.7};
        set_rgb(rgb, grey, 0.7 + 0.3 * vnoise(bf_v3_scale(p, 20.0), 61));
        break;
    }
    }
}

/* ------------------------------------------------------------ mesh builder */

typedef struct builder {
    mesh_data m;
    uint8_t *mat, *var;
    uint32_t cap_v, cap_t;
    bool is_oom;
} builder;

static bool reserve(builder *b, uint32_t add_v, uint32_t add_t)
{
    if (b->is_oom) return false;
    if (b->m.n_verts + add_v > b->cap_v) {
        uint32_t cap = b->cap_v ? b->cap_v : 4096;
        while (cap < b->m.n_verts + add_v) cap *= 2;
        float *xyz = realloc(b->m.xyz, sizeof(float) * 3 * cap);
        if (!xyz) return !(b->is_oom = true);
        b->m.xyz = xyz;
        b->cap_v = cap;
    }
    if (b->m.n_tris + add_t > b->cap_t) {
        uint32_t cap = b->cap_t ? b->cap_t : 4096;
        while (cap < b->m.n_tris + add_t) cap *= 2;
        uint32_t *tri = realloc(b->m.tri, sizeof(uint32_t) * 3 * cap);
        if (tri) b->m.tri = tri;
        uint8_t *mat = tri ? realloc(b->mat, cap) : NULL;
        if (mat) b->mat = mat;
        uint8_t *var = mat ? realloc(b->var, cap) : NULL;
        if (var) b->var = var;
        if (!var) return !(b->is_oom = true);
        b->cap_t = cap;
    }
    return true;
}

static void push_vert(builder *b, bf_vec3 p)
{
    float *o = b->m.xyz + 3 * (size_t)b->m.n_verts++;
    o[0] = (float)p.x;
    o[1] = (float)p.y;
    o[2] = (float)p.z;
}

static void push_tri(builder *b, uint32_t i0, uint32_t i1, uint32_t i2, uint8_t mat, uint8_t var)
{
    uint32_t t = b->m.n_tris++;
    b->m.tri[3 * (size_t)t] = i0;
    b->m.tri[3 * (size_t)t + 1] = i1;
    b->m.tri[3 * (size_t)t + 2] = i2;
    b->mat[t] = mat;
    b->var[t] = var;
}

/* The parallelogram p0 + a eu + b ev, a, b in [0, 1], cut into cells of at
 * most SYNTH_ROOM_CELL_M; its normal is eu x ev. */
static void add_quad(builder *b, bf_vec3 p0, bf_vec3 eu, bf_vec3 ev, uint8_t mat, uint8_t var)
{
    uint32_t nu = (uint32_t)ceil(bf_v3_norm(eu) / SYNTH_ROOM_CELL_M - 1e-9);
    uint32_t nv = (uint32_t)ceil(bf_v3_norm(ev) / SYNTH_ROOM_CELL_M - 1e-9);
    if (nu < 1) nu = 1;
    if (nv < 1) nv = 1;
    if (!reserve(b, (nu + 1) * (nv + 1), 2 * nu * nv)) return;
    uint32_t base = b->m.n_verts;
    for (uint32_t j = 0; j <= nv; j++)
        for (uint32_t i = 0; i <= nu; i++)
            push_vert(b, bf_v3_add(p0, bf_v3_add(bf_v3_scale(eu, (double)i / nu), bf_v3_scale(ev, (double)j / nv))));
    for (uint32_t j = 0; j < nv; j++)
        for (uint32_t i = 0; i < nu; i++) {
            uint32_t a = base + j * (nu + 1) + i, c = a + nu + 1;
            push_tri(b, a, a + 1, c + 1, mat, var);
            push_tri(b, a, c + 1, c, mat, var);
        }
}

/* An axis-aligned box; normals point out, or in for the room itself. The
 * variant of a wall says which way it runs (see the WALL texture). */
static void add_box(builder *b, bf_vec3 lo, bf_vec3 hi, uint8_t mat, uint8_t var, bool is_inward, bool skip_bottom)
{
    double sx = hi.x - lo.x, sy = hi.y - lo.y, sz = hi.z - lo.z;
    struct {
        bf_vec3 p0, eu, ev;
        uint8_t mat, var;
        bool is_bottom;
    } f[6] = {
        {bf_v3(hi.x, lo.y, lo.z), bf_v3(0, sy, 0), bf_v3(0, 0, sz), mat, var, false},
        {bf_v3(lo.x, lo.y, lo.z), bf_v3(0, 0, sz), bf_v3(0, sy, 0), mat, var, false},
        {bf_v3(lo.x, hi.y, lo.z), bf_v3(0, 0, sz), bf_v3(sx, 0, 0), mat, var, false},
        {bf_v3(lo.x, lo.y, lo.z), bf_v3(sx, 0, 0), bf_v3(0, 0, sz), mat, var, false},
        {bf_v3(lo.x, lo.y, hi.z), bf_v3(sx, 0, 0), bf_v3(0, sy, 0), mat, var, false},
        {bf_v3(lo.x, lo.y, lo.z), bf_v3(0, sy, 0), bf_v3(sx, 0, 0), mat, var, true},
    };
    if (is_inward) {
        /* The room: walls, floor, ceiling with their own materials. */
        f[0].var = f[1].var = 0;
        f[2].var = f[3].var = 1;
        f[4].mat = SYNTH_MAT_CEILING;
        f[5].mat = SYNTH_MAT_FLOOR;
    }
    for (int k = 0; k < 6; k++) {
        if (skip_bottom && f[k].is_bottom) continue;
        if (is_inward)
            add_quad(b, f[k].p0, f[k].ev, f[k].eu, f[k].mat, f[k].var);
        else
            add_quad(b, f[k].p0, f[k].eu, f[k].ev, f[k].mat, f[k].var);
    }
}

/* Area-weighted vertex normals (flat where faces share no vertices). */
static bool compute_normals(mesh_data *m)
{
    float *n = calloc((size_t)m->n_verts * 3 + 1, sizeof(float));
    if (!n) return false;
    for (uint32_t t = 0; t < m->n_tris; t++) {
        const uint32_t *v = m->tri + 3 * (size_t)t;
        const float *a = m->xyz + 3 * (size_t)v[0], *b = m->xyz + 3 * (size_t)v[1], *c = m->xyz + 3 * (size_t)v[2];
        bf_vec3 fn = bf_v3_cross(bf_v3(b[0] - a[0], b[1] - a[1], b[2] - a[2]), bf_v3(c[0] - a[0], c[1] - a[1], c[2] - a[2]));
        for (int k = 0; k < 3; k++) {
            float *o = n + 3 * (size_t)v[k];
            o[0] += (float)fn.x;
            o[1] += (float)fn.y;
            o[2] += (float)fn.z;
        }
    }
    for (uint32_t i = 0; i < m->n_verts; i++) {
        float *o = n + 3 * (size_t)i;
        bf_vec3 u = bf_v3_normalize(bf_v3(o[0], o[1], o[2]));
        o[0] = (float)u.x;
        o[1] = (float)u.y;
        o[2] = (float)u.z;
    }
    free(m->normal);
    m->normal = n;
    return true;
}

/* ------------------------------------------------------------ scenes */

bf_se3 synth_look_at(bf_vec3 eye_w, bf_vec3 target_w, bf_vec3 up_w)
{
    bf_vec3 z = bf_v3_normalize(bf_v3_sub(target_w, eye_w));
    bf_vec3 x = bf_v3_normalize(bf_v3_cross(z, up_w));
    if (bf_v3_norm(x) == 0) x = bf_v3_normalize(bf_v3_cross(z, bf_v3(1, 0, 0)));
    if (bf_v3_norm(x) == 0) x = bf_v3_normalize(bf_v3_cross(z, bf_v3(0, 1, 0)));
    bf_vec3 y = bf_v3_cross(z, x);
    bf_se3 T = bf_se3_identity();
    double cols[3][3] = {{x.x, x.y, x.z}, {y.x, y.y, y.z}, {z.x, z.y, z.z}};
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) T.R[r][c] = cols[c][r];
    T.t = eye_w;
    return T;
}

void synth_scene_free(synth_scene *s)
{
    if (!s) return;
    mesh_free(&s->mesh);
    free(s->tri_material);
    free(s->tri_variant);
    memset(s, 0, sizeof *s);
}

static void builder_free(builder *b)
{
    mesh_free(&b->m);
    free(b->mat);
    free(b->var);
}

/* One of the shared meshes standing on the table. */
typedef struct room_object {
    const char *file;
    int up_axis;       /* the model's up axis: 0 x, 1 y, 2 z */
    double height_m;   /* scaled to this height */
    double x, y;       /* where its box centre stands */
    double yaw_deg;    /* turned about z after standing it up */
    uint8_t variant;   /* colour */
} room_object;

#define TABLE_TOP_Z 0.76

static const room_object room_objects[] = {
    {"bunny.ply", 1, 0.18, 0.30, -0.12, -20, 7},
    {"armadillo.ply", 1, 0.25, 0.62, 0.18, 115, 1},
    {"dragon.ply", 1, 0.16, 0.95, -0.15, -65, 3},
};

static bf_status add_object(builder *b, const char *data_dir, const room_object *o, char *desc, size_t desc_cap)
{
    char sub[256], path[4096];
    snprintf(sub, sizeof sub, "meshes/%s", o->file);
    bf_status s = bf_path_join(path, sizeof path, data_dir, sub);
    if (s != BF_OK) return s;
    if (!bf_file_exists(path)) {
        bf_info("synth: room without %s (%s not found)", o->file, path);
        return BF_OK;
    }
    mesh_data m;
    if ((s = mesh_read_ply(path, &m))) return s;
    /* Stand it up (model up axis -> world z), turn it, scale it. */
    bf_quat q_up = o->up_axis == 1 ? bf_quat_from_axis_angle(bf_v3(1, 0, 0), M_PI / 2)
                 : o->up_axis == 0 ? bf_quat_from_axis_angle(bf_v3(0, 1, 0), -M_PI / 2)
                                   : bf_quat_identity();
    bf_quat q = bf_quat_mul(bf_quat_from_axis_angle(bf_v3(0, 0, 1), o->yaw_deg * M_PI / 180), q_up);
    bf_vec3 lo = bf_v3(INFINITY, INFINITY, INFINITY), hi = bf_v3(-INFINITY, -INFINITY, -INFINITY);
    for (uint32_t i = 0; i < m.n_verts; i++) {
        bf_vec3 p = bf_quat_rotate(q, bf_v3(m.xyz[3 * i], m.xyz[3 * i + 1], m.xyz[3 * i + 2]));
        lo = bf_v3(fmin(lo.x, p.x), fmin(lo.y, p.y), fmin(lo.z, p.z));
        hi = bf_v3(fmax(hi.x, p.x), fmax(hi.y, p.y), fmax(hi.z, p.z));
    }
    double scale = hi.z > lo.z ? o->height_m / (hi.z - lo.z) : 1.0;
    bf_vec3 shift = bf_v3(o->x - 0.5 * (lo.x + hi.x) * scale, o->y - 0.5 * (lo.y + hi.y) * scale, TABLE_TOP_Z - lo.z * scale);
    if (!reserve(b, m.n_verts, m.n_tris)) {
        mesh_free(&m);
        return bf_fail(BF_NO_MEMORY, "synth: room: out of memory for %s", path);
    }
    uint32_t base = b->m.n_verts;
    for (uint32_t i = 0; i < m.n_verts; i++) {
        bf_vec3 p = bf_quat_rotate(q, bf_v3(m.xyz[3 * i], m.xyz[3 * i + 1], m.xyz[3 * i + 2]));
        push_vert(b, bf_v3_add(bf_v3_scale(p, scale), shift));
    }
    for (uint32_t t = 0; t < m.n_tris; t++)
        push_tri(b, base + m.tri[3 * t], base + m.tri[3 * t + 1], base + m.tri[3 * t + 2], SYNTH_MAT_OBJECT, o->variant);
    size_t len = strlen(desc);
    snprintf(desc + len, desc_cap - len, ", %s (%u triangles, %.0f cm)", o->file, m.n_tris, o->height_m * 100);
    mesh_free(&m);
    return BF_OK;
}

static bf_status scene_take(builder *b, const bf_se3 *T_view, bf_vec3 light_w, synth_scene *out)
{
    if (b->is_oom || !compute_normals(&b->m)) {
        builder_free(b);
        return bf_fail(BF_NO_MEMORY, "synth: out of memory building the scene");
    }
    memset(out, 0, sizeof *out);
    out->mesh = b->m;
    out->tri_material = b->mat;
    out->tri_variant = b->var;
    out->T_wc_view = *T_view;
    out->light_w = light_w;
    return BF_OK;
}

bf_status synth_scene_room(const char *data_dir, synth_scene *out)
{
    builder b = {0};
    char desc[sizeof out->desc];
    snprintf(desc, sizeof desc, "room 4 x 3.5 x 2.5 m, table, 4 boxes");
    add_box(&b, bf_v3(-2, -1.75, 0), bf_v3(2, 1.75, 2.5), SYNTH_MAT_WALL, 0, true, false);
    /* Table: top and four legs. */
    double tx = 0.6, ty = 0, hx = 0.6, hy = 0.4, leg = 0.05;
    add_box(&b, bf_v3(tx - hx, ty - hy, TABLE_TOP_Z - 0.04), bf_v3(tx + hx, ty + hy, TABLE_TOP_Z), SYNTH_MAT_TABLE, 0, false,
            false);
    for (int k = 0; k < 4; k++) {
        double lx = k & 1 ? tx + hx - 0.05 - leg : tx - hx + 0.05, ly = k & 2 ? ty + hy - 0.05 - leg : ty - hy + 0.05;
        add_box(&b, bf_v3(lx, ly, 0), bf_v3(lx + leg, ly + leg, TABLE_TOP_Z - 0.04), SYNTH_MAT_TABLE, 0, false, true);
    }
    /* Boxes on the table and on the floor (bottoms hidden, left out). */
    add_box(&b, bf_v3(0.80, 0.05, TABLE_TOP_Z), bf_v3(0.96, 0.17, TABLE_TOP_Z + 0.10), SYNTH_MAT_BOX, 0, false, true);
    add_box(&b, bf_v3(0.12, 0.12, TABLE_TOP_Z), bf_v3(0.22, 0.22, TABLE_TOP_Z + 0.22), SYNTH_MAT_BOX, 2, false, true);
    add_box(&b, bf_v3(1.30, -1.45, 0), bf_v3(1.80, -1.05, 0.45), SYNTH_MAT_BOX, 1, false, true);
    add_box(&b, bf_v3(1.40, 1.00, 0), bf_v3(1.80, 1.40, 0.70), SYNTH_MAT_BOX, 3, false, true);
    if (data_dir) {
        for (size_t i = 0; i < sizeof room_objects / sizeof room_objects[0]; i++) {
            bf_status s = add_object(&b, data_dir, &room_objects[i], desc, sizeof desc);
            if (s != BF_OK) {
                builder_free(&b);
                return s;
            }
        }
    } else {
        bf_info("synth: room without the shared meshes (no data folder)");
    }
    bf_se3 T_view = synth_look_at(bf_v3(-0.9, -0.7, 1.45), bf_v3(0.6, 0, 0.85), bf_v3(0, 0, 1));
    bf_status s = scene_take(&b, &T_view, bf_v3(0.2, -0.4, 2.3), out);
    if (s == BF_OK) snprintf(out->desc, sizeof out->desc, "%s", desc);
    return s;
}

/* A number in [0, 1) from (room, item): the rooms' furniture varies, the
 * same every time. */
static double room_rand(int room, int item) { return hash01(room, item, 7, 0x524f4f4d53ull); }

bf_status synth_scene_rooms(uint32_t n, synth_scene *out)
{
    if (n < 1 || n > 64) return bf_fail(BF_INVALID_ARG, "synth: rooms:%u: 1 to 64 rooms", n);
    builder b = {0};
    const double L = 4.0, W = 3.5, H = 2.5, door_w = 1.6, door_h = 2.3, wall = 0.1;
    /* One long box, then a partition with a doorway between neighbours. */
    add_box(&b, bf_v3(-2, -W / 2, 0), bf_v3(-2 + n * L, W / 2, H), SYNTH_MAT_WALL, 0, true, false);
    for (uint32_t r = 0; r < n; r++) {
        double x0 = -2 + r * L;
        if (r > 0) {
            /* Doorways alternate to either side of the middle line, which
             * passes through all of them while no view runs down the row. */
            double dy = r % 2 ? 0.6 : -0.6;
            add_box(&b, bf_v3(x0 - wall / 2, -W / 2, 0), bf_v3(x0 + wall / 2, dy - door_w / 2, H), SYNTH_MAT_WALL,
                    (uint8_t)(r % 4), false, true);
            add_box(&b, bf_v3(x0 - wall / 2, dy + door_w / 2, 0), bf_v3(x0 + wall / 2, W / 2, H), SYNTH_MAT_WALL,
                    (uint8_t)(r % 4), false, true);
            add_box(&b, bf_v3(x0 - wall / 2, dy - door_w / 2, door_h), bf_v3(x0 + wall / 2, dy + door_w / 2, H),
                    SYNTH_MAT_WALL, (uint8_t)(r % 4), false, true);
        }
        /* A table against one side wall and boxes along both, away from the
         * middle of the room so a walk through the doorways stays clear. */
        double side = room_rand(r, 1) < 0.5 ? -1 : 1;
        double tx = x0 + 1.0 + 1.6 * room_rand(r, 2), ty = side * (W / 2 - 0.5);
        add_box(&b, bf_v3(tx - 0.6, ty - 0.35, TABLE_TOP_Z - 0.04), bf_v3(tx + 0.6, ty + 0.35, TABLE_TOP_Z),
                SYNTH_MAT_TABLE, 0, false, false);
        for (int k = 0; k < 4; k++) {
            double lx = k & 1 ? tx + 0.5 : tx - 0.55, ly = k & 2 ? ty + 0.25 : ty - 0.3;
            add_box(&b, bf_v3(lx, ly, 0), bf_v3(lx + 0.05, ly + 0.05, TABLE_TOP_Z - 0.04), SYNTH_MAT_TABLE, 0, false,
                    true);
        }
        for (int k = 0; k < 4; k++) {
            double bx = x0 + 0.4 + 3.0 * room_rand(r, 10 + k), by = (k & 1 ? 1 : -1) * (W / 2 - 0.3);
            double sx = 0.2 + 0.3 * room_rand(r, 20 + k), sz = 0.2 + 0.8 * room_rand(r, 30 + k);
            add_box(&b, bf_v3(bx - sx / 2, by - 0.2, 0), bf_v3(bx + sx / 2, by + 0.2, sz), SYNTH_MAT_BOX,
                    (uint8_t)((r + k) % 4), false, true);
        }
        /* Shelves on both side walls at eye height and a pillar by the
         * doorway: structure across the walk, which the walls alone leave
         * unconstrained sideways. */
        for (int k = 0; k < 2; k++) {
            double sx = x0 + 0.5 + 2.5 * room_rand(r, 50 + k), sy = (k ? 1 : -1) * (W / 2 - 0.15);
            double z0 = 1.0 + 0.4 * room_rand(r, 60 + k);
            add_box(&b, bf_v3(sx, sy - 0.15, z0), bf_v3(sx + 0.7, sy + 0.15, z0 + 0.5 + 0.4 * room_rand(r, 70 + k)),
                    SYNTH_MAT_BOX, (uint8_t)((r + k + 1) % 4), false, false);
        }
        if (r + 1 < n) {
            double px = x0 + L - 0.45, py = (room_rand(r, 80) < 0.5 ? -1 : 1) * (door_w / 2 + 0.15);
            add_box(&b, bf_v3(px - 0.12, py - 0.12, 0), bf_v3(px + 0.12, py + 0.12, H), SYNTH_MAT_BOX, 2, false, true);
        }
        double ox = x0 + 1.0 + 2.0 * room_rand(r, 40);
        add_box(&b, bf_v3(ox - 0.1, ty - 0.1, TABLE_TOP_Z), bf_v3(ox + 0.1, ty + 0.1, TABLE_TOP_Z + 0.25), SYNTH_MAT_BOX,
                (uint8_t)(r % 4), false, true);
    }
    /* The first camera stands in the first room looking down the row. */
    bf_se3 T_view = synth_look_at(bf_v3(-1.5, 0, 1.4), bf_v3(0, 0, 1.4), bf_v3(0, 0, 1));
    bf_status s = scene_take(&b, &T_view, bf_v3(-2 + n * L / 2, 0, 2.3), out);
    if (s == BF_OK)
        snprintf(out->desc, sizeof out->desc, "%u rooms of 4 x 3.5 x 2.5 m in a row along x (%.0f m), doorways, "
                 "tables and boxes", n, n * L);
    return s;
}

bf_status synth_scene_from_mesh(mesh_data *mesh, const bf_se3 *T_wc_view, synth_scene *out)
{
    builder b = {0};
    b.m = *mesh;
    memset(mesh, 0, sizeof *mesh);
    b.mat = calloc(b.m.n_tris + 1, 1);
    b.var = calloc(b.m.n_tris + 1, 1);
    if (!b.mat || !b.var) b.is_oom = true;
    bf_vec3 lo = bf_v3(INFINITY, INFINITY, INFINITY), hi = bf_v3(-INFINITY, -INFINITY, -INFINITY);
    for (uint32_t i = 0; i < b.m.n_verts; i++) {
        const float *p = b.m.xyz + 3 * (size_t)i;
        lo = bf_v3(fmin(lo.x, p[0]), fmin(lo.y, p[1]), fmin(lo.z, p[2]));
        hi = bf_v3(fmax(hi.x, p[0]), fmax(hi.y, p[1]), fmax(hi.z, p[2]));
    }
    /* Light above the viewer's shoulder. */
    bf_vec3 light = bf_v3_add(T_wc_view->t, bf_se3_rotate(T_wc_view, bf_v3(0.5, -1.0, 0)));
    bf_status s = scene_take(&b, T_wc_view, light, out);
    if (s == BF_OK) snprintf(out->desc, sizeof out->desc, "mesh, %u triangles", out->mesh.n_tris);
    return s;
}

bf_status synth_scene_from_ply(const char *path, double scale, synth_scene *out)
{
    if (!(scale > 0) || !isfinite(scale)) return bf_fail(BF_INVALID_ARG, "%s: scale %g is not positive", path, scale);
    mesh_data m;
    bf_status s = mesh_read_ply(path, &m);
    if (s != BF_OK) return s;
    if (m.n_tris == 0) {
        mesh_free(&m);
        return bf_fail(BF_FORMAT, "%s: no triangles to render", path);
    }
    bf_vec3 lo = bf_v3(INFINITY, INFINITY, INFINITY), hi = bf_v3(-INFINITY, -INFINITY, -INFINITY);
    /* The mesh's local origin (a far PLY's, mesh_read_ply) folded in: the
     * scene is the file's points times the scale. */
    const double o[3] = {m.origin.x, m.origin.y, m.origin.z};
    for (uint32_t i = 0; i < 3 * m.n_verts; i++) m.xyz[i] = (float)((o[i % 3] + (double)m.xyz[i]) * scale);
    m.origin = bf_v3(0, 0, 0);
    for (uint32_t i = 0; i < m.n_verts; i++) {
        const float *p = m.xyz + 3 * (size_t)i;
        lo = bf_v3(fmin(lo.x, p[0]), fmin(lo.y, p[1]), fmin(lo.z, p[2]));
        hi = bf_v3(fmax(hi.x, p[0]), fmax(hi.y, p[1]), fmax(hi.z, p[2]));
    }
    bf_vec3 c = bf_v3_scale(bf_v3_add(lo, hi), 0.5);
    double r = 0.5 * bf_v3_norm(bf_v3_sub(hi, lo));
    /* The bounding sphere fills the height of a 525 px / 480 row image. */
    double dist = 1.1 * r / sin(atan(240.0 / 525.0));
    if (dist > SYNTH_KINECT1_Z_MAX_M || dist - r < SYNTH_KINECT1_Z_MIN_M)
        bf_warn("synth: %s: the view stands %.2f m from the mesh (radius %.3g m), outside the Kinect range "
                "%.1f-%.1f m; use --scale", path, dist, r, SYNTH_KINECT1_Z_MIN_M, SYNTH_KINECT1_Z_MAX_M);
    bf_se3 T_view = synth_look_at(bf_v3(c.x, c.y, c.z + dist), c, bf_v3(0, 1, 0));
    s = synth_scene_from_mesh(&m, &T_view, out);
    if (s == BF_OK) snprintf(out->desc, sizeof out->desc, "%s x %g, %u triangles", path, scale, out->mesh.n_tris);
    return s;
}
