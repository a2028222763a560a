/* The window (GLFW), its input, and showing a ray-cast in it. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "shaders/view.glsl.h"
#include "view_int.h"

/* After vulkan.h (through gpu.h): GLFW declares its Vulkan calls only then. */
#include <GLFW/glfw3.h>

#include <dlfcn.h>

/* GLFW is opened at run time, as gpu/ opens the Vulkan loader: a machine
 * without libglfw3 runs every headless command and view_open says what is
 * missing. The functions view/ calls, typed from GLFW's own header: */
#define VIEW__GLFW(X) \
    X(glfwCreateWindow) \
    X(glfwCreateWindowSurface) \
    X(glfwDestroyWindow) \
    X(glfwGetFramebufferSize) \
    X(glfwGetMouseButton) \
    X(glfwGetRequiredInstanceExtensions) \
    X(glfwGetWindowUserPointer) \
    X(glfwInit) \
    X(glfwPollEvents) \
    X(glfwSetCursorPosCallback) \
    X(glfwSetErrorCallback) \
    X(glfwSetKeyCallback) \
    X(glfwSetScrollCallback) \
    X(glfwSetWindowShouldClose) \
    X(glfwSetWindowTitle) \
    X(glfwSetWindowUserPointer) \
    X(glfwTerminate) \
    X(glfwVulkanSupported) \
    X(glfwWaitEventsTimeout) \
    X(glfwWindowHint) \
    X(glfwWindowShouldClose)

static struct {
    void *lib; /* loaded once, never closed (GLFW may keep X11 state) */
#define VIEW__MEMBER(fn) __typeof__(&fn) fn;
    VIEW__GLFW(VIEW__MEMBER)
#undef VIEW__MEMBER
} gl;

static bf_status load_glfw(void)
{
    if (gl.lib) return BF_OK;
    void *lib = dlopen("libglfw.so.3", RTLD_NOW | RTLD_LOCAL);
    if (!lib) return bf_fail(BF_NO_DEVICE, "view: cannot load GLFW for the window: %s (Debian: libglfw3)", dlerror());
#define VIEW__LOAD(fn)                                                                              \
    if (!(*(void **)&gl.fn = dlsym(lib, #fn))) {                                                    \
        dlclose(lib);                                                                               \
        return bf_fail(BF_NO_DEVICE, "view: libglfw.so.3 has no %s (GLFW 3.3 or newer needed)", #fn); \
    }
    VIEW__GLFW(VIEW__LOAD)
#undef VIEW__LOAD
    gl.lib = lib;
    return BF_OK;
}

struct view_window {
    view_config cfg;
    GLFWwindow *window;
    const char **extensions;     /* GLFW's, for gpu_config */
    uint32_t n_extensions;

    /* input since the last view_poll */
    double cursor_x, cursor_y;
    bool has_cursor;
    double orbit_x, orbit_y, pan_x, pan_y, scroll;
    bool is_following, toggle_follow;

    view__camera cam;
    bf_se3 T_follow;             /* the scan's newest pose */
    bool has_follow_pose;

    gpu_context *ctx;            /* attached: */
    gpu_swapchain *sc;
    gpu_pipeline *blit;
    gpu_bindings *binds;
    gpu_buffer *pixels;          /* the swapchain image's pixels before the copy */
    gpu_buffer *readback;        /* screenshots; made on first use */
    gpu_buffer *glyphs;          /* the overlay's glyphs, one per character (UPLOAD) */
    uint32_t width, height;      /* the swapchain's */
    char title[256];
    char line[VIEW_TEXT_MAX + 1]; /* the overlay's text */
};

static char g_glfw_error[512];

static void on_glfw_error(int code, const char *msg)
{
    snprintf(g_glfw_error, sizeof g_glfw_error, "%s (GLFW error 0x%x)", msg ? msg : "", code);
}

view_config view_config_default(void)
{
    return (view_config){.width = 640, .height = 480, .title = "bitfuse", .orbit_deg_per_px = 0.3,
                         .zoom_per_notch = 0.1, .overlay = true};
}

/* ------------------------------------------------------------ input */

static void on_cursor(GLFWwindow *w, double x, double y)
{
    view_window *v = gl.glfwGetWindowUserPointer(w);
    if (v->has_cursor) {
        double dx = x - v->cursor_x, dy = y - v->cursor_y;
        if (gl.glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS) {
            v->orbit_x += dx;
            v->orbit_y += dy;
        } else if (gl.glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS ||
                   gl.glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS) {
            v->pan_x += dx;
            v->pan_y += dy;
        }
    }
    v->cursor_x = x;
    v->cursor_y = y;
    v->has_cursor = true;
}

static void on_scroll(GLFWwindow *w, double dx, double dy)
{
    (void)dx;
    view_window *v = gl.glfwGetWindowUserPointer(w);
    v->scroll += dy;
}

static void on_key(GLFWwindow *w, int key, int scancode, int action, int mods)
{
    (void)scancode, (void)mods;
    view_window *v = gl.glfwGetWindowUserPointer(w);
    if (action != GLFW_PRESS) return;
    if (key == GLFW_KEY_ESCAPE || key == GLFW_KEY_Q) gl.glfwSetWindowShouldClose(w, GLFW_TRUE);
    if (key == GLFW_KEY_F) v->toggle_follow = true;
}

/* ------------------------------------------------------------ window */

static bf_status make_surface(void *user, VkInstance instance, VkSurfaceKHR *out)
{
    view_window *v = user;
    g_glfw_error[0] = '\0';
    VkResult r = gl.glfwCreateWindowSurface(instance, v->window, NULL, out);
    if (r != VK_SUCCESS)
        return bf_fail(BF_UNSUPPORTED, "view: cannot make a Vulkan surface for the window (VkResult %d%s%s)", (int)r,
                       g_glfw_error[0] ? ": " : "", g_glfw_error);
    return BF_OK;
}

bf_status view_open(const view_config *cfg, gpu_config *gcfg, view_window **out)
{
    view_window *v = bf_calloc(1, sizeof *v);
    if (!v) return bf_fail(BF_NO_MEMORY, "view: window");
    v->cfg = cfg ? *cfg : view_config_default();
    if (!v->cfg.title) v->cfg.title = "bitfuse";
    if (v->cfg.width == 0 || v->cfg.height == 0 || v->cfg.width > 16384 || v->cfg.height > 16384) {
        bf_status bad = bf_fail(BF_INVALID_ARG, "view: window size %ux%u", v->cfg.width, v->cfg.height);
        free(v);
        return bad;
    }
    bf_status s = load_glfw();
    if (s != BF_OK) {
        free(v);
        return s;
    }
    g_glfw_error[0] = '\0';
    gl.glfwSetErrorCallback(on_glfw_error);
    if (!gl.glfwInit()) {
        const char *d = getenv("DISPLAY");
        free(v);
        return bf_fail(BF_NO_DEVICE, "view: no display to open a window on (DISPLAY=%s%s%s; for scripts, xvfb-run)",
                       d ? d : "unset", g_glfw_error[0] ? ": " : "", g_glfw_error);
    }
    if (!gl.glfwVulkanSupported()) {
        s = bf_fail(BF_NO_DEVICE, "view: GLFW finds no Vulkan loader for presentation%s%s", g_glfw_error[0] ? ": " : "",
                    g_glfw_error);
        goto fail;
    }
    uint32_t n = 0;
    v->extensions = gl.glfwGetRequiredInstanceExtensions(&n);
    v->n_extensions = n;
    if (!v->extensions) {
        s = bf_fail(BF_NO_DEVICE, "view: the Vulkan instance cannot present to this display%s%s",
                    g_glfw_error[0] ? ": " : "", g_glfw_error);
        goto fail;
    }
    gl.glfwWindowHint(GLFW_CLIENT_API, GLFW_NO_API);
    v->window = gl.glfwCreateWindow((int)v->cfg.width, (int)v->cfg.height, v->cfg.title, NULL, NULL);
    if (!v->window) {
        s = bf_fail(BF_NO_DEVICE, "view: cannot open a window%s%s", g_glfw_error[0] ? ": " : "", g_glfw_error);
        goto fail;
    }
    gl.glfwSetWindowUserPointer(v->window, v);
    gl.glfwSetCursorPosCallback(v->window, on_cursor);
    gl.glfwSetScrollCallback(v->window, on_scroll);
    gl.glfwSetKeyCallback(v->window, on_key);
    v->is_following = v->cfg.is_following;
    bf_se3 I = bf_se3_identity();
    v->cam = view__camera_make(&I, 1.0);
    v->T_follow = I;
    snprintf(v->title, sizeof v->title, "%s", v->cfg.title);
    gcfg->surface_extensions = v->extensions;
    gcfg->n_surface_extensions = v->n_extensions;
    gcfg->make_surface = make_surface;
    gcfg->surface_user = v;
    *out = v;
    return BF_OK;
fail:
    view_destroy(v);
    return s;
}

void view_destroy(view_window *v)
{
    if (!v) return;
    BF_ASSERT(!v->ctx); /* view_detach first, while the context lives */
    if (v->window) gl.glfwDestroyWindow(v->window);
    gl.glfwTerminate();
    free(v);
}

bool view_poll(view_window *v)
{
    gl.glfwPollEvents();
    const double k = v->cfg.orbit_deg_per_px * M_PI / 180.0;
    bool moved = v->orbit_x || v->orbit_y || v->pan_x || v->pan_y || v->scroll;
    if (moved && v->is_following) {
        /* A drag takes the camera from where the scan's camera is. */
        v->cam = view__camera_make(&v->T_follow, v->cam.pivot_m);
        v->is_following = false;
    }
    if (v->orbit_x || v->orbit_y) view__camera_orbit(&v->cam, -k * v->orbit_x, -k * v->orbit_y);
    uint32_t w = v->width ? v->width : v->cfg.width;
    double fx = v->cfg.fx_px > 0 ? v->cfg.fx_px : 525.0 * v->cfg.width / 640.0;
    if (v->pan_x || v->pan_y) view__camera_pan(&v->cam, v->pan_x, v->pan_y, fx * w / v->cfg.width);
    if (v->scroll) view__camera_zoom(&v->cam, v->scroll, v->cfg.zoom_per_notch);
    v->orbit_x = v->orbit_y = v->pan_x = v->pan_y = v->scroll = 0;
    if (v->toggle_follow && v->has_follow_pose) { /* only a scan has a camera to follow */
        v->is_following = !v->is_following;
        if (!v->is_following) v->cam = view__camera_make(&v->T_follow, v->cam.pivot_m);
    }
    v->toggle_follow = false;
    return !gl.glfwWindowShouldClose(v->window);
}

bool view_should_close(const view_window *v) { return gl.glfwWindowShouldClose(v->window); }

void view_wait(view_window *v, double timeout_s)
{
    (void)v;
    gl.glfwWaitEventsTimeout(timeout_s);
}

void view_set_pose(view_window *v, const bf_se3 *T_wc, double pivot_m)
{
    v->cam = view__camera_make(T_wc, pivot_m);
    v->is_following = false;
}

void view_follow(view_window *v, const bf_se3 *T_wc)
{
    v->T_follow = *T_wc;
    v->has_follow_pose = true;
}

bool view_is_following(const view_window *v) { return v->is_following; }

bf_se3 view_pose(const view_window *v) { return v->is_following && v->has_follow_pose ? v->T_follow : v->cam.T_wc; }

void view_size(const view_window *v, uint32_t *width, uint32_t *height)
{
    *width = v->width ? v->width : v->cfg.width;
    *height = v->height ? v->height : v->cfg.height;
}

/* The overlay's line: the title's facts, shorter. */
static void set_line(view_window *v, const view_status *st)
{
    char *t = v->line;
    size_t cap = sizeof v->line;
    int n = 0;
    if (st->has_frame) n += snprintf(t + n, cap - (size_t)n, "frame %u | ", st->frame);
    if (st->state) n += snprintf(t + n, cap - (size_t)n, "%s | ", st->state);
    n += snprintf(t + n, cap - (size_t)n, "%llu bricks", (unsigned long long)st->n_bricks);
    if (st->map_mib > 0) n += snprintf(t + n, cap - (size_t)n, " %.1f mib", st->map_mib);
    if (st->has_frame) snprintf(t + n, cap - (size_t)n, " | %s", v->is_following ? "follow" : "free (f: follow)");
}

void view_set_status(view_window *v, const view_status *st)
{
    set_line(v, st);
    char t[256];
    int n = snprintf(t, sizeof t, "%s", v->cfg.title);
    if (st->has_frame) n += snprintf(t + n, sizeof t - (size_t)n, " | frame %u", st->frame);
    if (st->state) n += snprintf(t + n, sizeof t - (size_t)n, " | %s", st->state);
    n += snprintf(t + n, sizeof t - (size_t)n, " | %llu bricks", (unsigned long long)st->n_bricks);
    if (st->map_mib > 0) n += snprintf(t + n, sizeof t - (size_t)n, " (%.1f MiB)", st->map_mib);
    snprintf(t + n, sizeof t - (size_t)n, " | %s", v->is_following ? "following the camera (drag to look around)"
                                                                     : "free camera (F: follow)");
    if (strcmp(t, v->title) != 0) {
        snprintf(v->title, sizeof v->title, "%s", t);
        gl.glfwSetWindowTitle(v->window, v->title);
    }
}

void view_set_overlay(view_window *v, bool on) { v->cfg.overlay = on; }

/* ------------------------------------------------------------ GPU side */

static bf_status make_size_buffers(view_window *v)
{
    gpu_swapchain_info si = gpu_swapchain_get_info(v->sc);
    gpu_buffer_destroy(v->pixels);
    gpu_buffer_destroy(v->readback);
    v->pixels = v->readback = NULL;
    v->width = si.width;
    v->height = si.height;
    gpu_buffer_desc d = {.name = "view.pixels", .size_bytes = 4ull * si.width * si.height, .memory = GPU_MEMORY_DEVICE};
    bf_status s = gpu_buffer_create(v->ctx, &d, &v->pixels);
    if (s == BF_OK) s = gpu_bindings_set(v->binds, 1, v->pixels, 0, GPU_WHOLE_SIZE);
    return s;
}

bf_status view_attach(view_window *v, gpu_context *ctx)
{
    BF_ASSERT(!v->ctx);
    v->ctx = ctx;
    int fw = 0, fh = 0;
    gl.glfwGetFramebufferSize(v->window, &fw, &fh);
    bf_status s = gpu_swapchain_create(ctx, fw > 0 ? (uint32_t)fw : v->cfg.width, fh > 0 ? (uint32_t)fh : v->cfg.height,
                                       &v->sc);
    gpu_pipeline_desc pd = {
        .name = "view.blit",
        .spirv = bf_spv_view_blit,
        .spirv_bytes = bf_spv_view_blit_size,
        .n_buffers = 3,
        .push_bytes = sizeof(struct view_push),
        .local_size = {VIEW_LOCAL_X, VIEW_LOCAL_Y, 1},
    };
    if (s == BF_OK) s = gpu_pipeline_create(ctx, &pd, &v->blit);
    if (s == BF_OK) s = gpu_bindings_create(ctx, 3, "view.blit", &v->binds);
    gpu_buffer_desc gd = {.name = "view.glyphs", .size_bytes = 4 * VIEW_TEXT_MAX, .memory = GPU_MEMORY_UPLOAD};
    if (s == BF_OK) s = gpu_buffer_create(ctx, &gd, &v->glyphs);
    if (s == BF_OK) s = gpu_bindings_set(v->binds, 2, v->glyphs, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = make_size_buffers(v);
    if (s == BF_OK) {
        gpu_swapchain_info si = gpu_swapchain_get_info(v->sc);
        bf_info("view: %ux%u window, %u images, %s, %s presentation", si.width, si.height, si.n_images,
                si.is_bgra ? "BGRA" : "RGBA", si.present_mode);
    }
    if (s != BF_OK) view_detach(v);
    return s;
}

void view_detach(view_window *v)
{
    if (!v || !v->ctx) return;
    gpu_swapchain_destroy(v->sc); /* waits for the device */
    gpu_buffer_destroy(v->readback);
    gpu_buffer_destroy(v->pixels);
    gpu_buffer_destroy(v->glyphs);
    gpu_bindings_destroy(v->binds);
    gpu_pipeline_destroy(v->blit);
    v->sc = NULL;
    v->readback = v->pixels = v->glyphs = NULL;
    v->binds = NULL;
    v->blit = NULL;
    v->ctx = NULL;
}

static bf_status remake(view_window *v)
{
    int fw = 0, fh = 0;
    gl.glfwGetFramebufferSize(v->window, &fw, &fh);
    bf_status s = gpu_swapchain_resize(v->sc, fw > 0 ? (uint32_t)fw : 1, fh > 0 ? (uint32_t)fh : 1);
    if (s == BF_OK) s = make_size_buffers(v);
    return s;
}

bf_status view_show(view_window *v, const render_targets *t, uint8_t *rgb, bool *is_shown)
{
    BF_ASSERT(v->ctx);
    if (is_shown) *is_shown = false;
    int fw = 0, fh = 0;
    gl.glfwGetFramebufferSize(v->window, &fw, &fh);
    if (fw <= 0 || fh <= 0) return BF_OK; /* minimised: nothing to show */
    bf_status s = BF_OK;
    if ((uint32_t)fw != v->width || (uint32_t)fh != v->height) s = remake(v);
    bool is_stale = false;
    if (s == BF_OK) s = gpu_swapchain_acquire(v->sc, &is_stale);
    if (s != BF_OK || is_stale) return s == BF_OK ? remake(v) : s;
    gpu_swapchain_info si = gpu_swapchain_get_info(v->sc);
    if (rgb && !si.can_read) return bf_fail(BF_UNSUPPORTED, "view: the window's images cannot be read back");
    if (rgb && !v->readback) {
        gpu_buffer_desc d = {.name = "view.readback", .size_bytes = 4ull * v->width * v->height,
                             .memory = GPU_MEMORY_READBACK, .usage = GPU_USAGE_TRANSFER};
        s = gpu_buffer_create(v->ctx, &d, &v->readback);
    }
    /* Bound every frame: a caster remade at the same address (a resized
     * window) must not leave the set pointing at its destroyed buffer. The
     * last submission has finished, so the set may change. */
    if (s == BF_OK) s = gpu_bindings_set(v->binds, 0, t->colour, 0, GPU_WHOLE_SIZE);
    /* The glyphs: the previous submission has finished with the buffer. */
    uint32_t n_chars = v->cfg.overlay ? (uint32_t)strlen(v->line) : 0;
    uint32_t *g = gpu_buffer_map(v->glyphs);
    for (uint32_t i = 0; i < n_chars; i++) g[i] = view__glyph(v->line[i]);
    if (s == BF_OK && n_chars) s = gpu_buffer_flush(v->glyphs);
    if (s == BF_OK) s = gpu_begin(v->ctx);
    if (s != BF_OK) return s;
    struct view_push pc = {.src_w = t->width, .src_h = t->height, .dst_w = v->width, .dst_h = v->height,
                           .is_bgra = si.is_bgra, .n_chars = n_chars,
                           .scale = v->width >= 640 ? v->width / 320 : 1};
    gpu_cmd_label_begin(v->ctx, "view.show");
    /* The ray-cast's colour (finished: its submission was waited for) ->
     * the blit; the blit's writes -> the copy into the image. */
    gpu_cmd_dispatch(v->ctx, v->blit, v->binds, &pc, gpu_groups(v->width, VIEW_LOCAL_X),
                     gpu_groups(v->height, VIEW_LOCAL_Y), 1);
    gpu_cmd_barrier(v->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
    gpu_cmd_copy_to_swapchain(v->ctx, v->sc, v->pixels, 0, rgb ? v->readback : NULL);
    gpu_cmd_label_end(v->ctx);
    s = gpu_submit_present(v->ctx, v->sc, &is_stale);
    uint32_t *px = NULL;
    size_t n_px = (size_t)v->width * v->height;
    if (s == BF_OK && rgb && !(px = malloc(4 * n_px))) s = bf_fail(BF_NO_MEMORY, "view: screenshot");
    if (s == BF_OK && rgb) s = gpu_buffer_download(v->readback, 0, px, 4 * n_px);
    if (s == BF_OK && rgb) {
        for (size_t i = 0; i < n_px; i++) {
            uint32_t p = px[i];
            uint8_t a = p & 0xff, b = (p >> 8) & 0xff, c = (p >> 16) & 0xff;
            rgb[3 * i + 0] = si.is_bgra ? c : a;
            rgb[3 * i + 1] = b;
            rgb[3 * i + 2] = si.is_bgra ? a : c;
        }
    }
    free(px);
    if (s == BF_OK && is_shown) *is_shown = true;
    if (s == BF_OK && is_stale) s = remake(v);
    return s;
}
