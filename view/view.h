/* view: a window that shows the ray-cast of a map (DESIGN.md section 1,
 * "show"; docs/view.md). GLFW opens the window (X11 on Debian), gpu/ makes
 * the Vulkan surface and swapchain on the context's compute queue, and a
 * tiny compute pass (shaders/view_blit.comp) copies render/'s shaded RGBA8
 * image into the swapchain's byte order; no graphics pipeline. The caller
 * ray-casts (render_raycast, or recon_render_view in a scan) at the pose
 * the window's camera gives and hands over the targets.
 *
 * The camera: orbit about a pivot point in front of it (left drag), pan
 * (right or middle drag), zoom towards the pivot (wheel); F follows the
 * scanning camera again (the default while a scan is given poses, left at
 * the first drag), Esc or Q closes. Orbit turns about the world's "up" of
 * the pose the camera was set to, so the horizon never rolls.
 *
 * Order of life: view_open (before the GPU context: it fills the context's
 * presentation fields), gpu_context_create, view_attach, frames,
 * view_detach (before gpu_context_destroy), view_destroy (after it: the
 * window outlives its surface). Threading: one thread, GLFW's main thread.
 */
#ifndef BF_VIEW_H
#define BF_VIEW_H

#include "core/core.h"
#include "gpu/gpu.h"
#include "render/render.h"

typedef struct view_window view_window; /* opaque */

typedef struct view_config {
    uint32_t width, height;   /* the window's first size [px], default 640 x 480 */
    const char *title;        /* default "bitfuse" */
    double orbit_deg_per_px;  /* turn per pixel dragged, default 0.3 */
    double zoom_per_notch;    /* fraction of the pivot distance one wheel notch moves, default 0.1 */
    double fx_px;             /* the casts' focal length at width (pan follows the cursor); 0: 525 * width / 640 */
    bool is_following;        /* start following the scanning camera (view_follow) */
    bool overlay;             /* the status line also over the image's top left corner, default on */
} view_config;

view_config view_config_default(void);

/* Opens the window and sets gcfg's presentation fields (surface extensions
 * and the surface maker) so that gpu_context_create(gcfg) presents to it;
 * gcfg's other fields are left alone, and it must not outlive the window.
 * BF_NO_DEVICE without a display (DISPLAY unset, X server gone) or without
 * Vulkan presentation in GLFW, the message saying which. */
bf_status view_open(const view_config *cfg, gpu_config *gcfg, view_window **out);
/* The swapchain, blit pipeline and buffers on ctx (made from the gcfg that
 * view_open filled; borrowed, must outlive view_detach). BF_UNSUPPORTED
 * when the device cannot present to the window. */
bf_status view_attach(view_window *v, gpu_context *ctx);
/* Releases what view_attach made; waits for the device. No-op when not attached. */
void view_detach(view_window *v);
/* Closes the window; after gpu_context_destroy. NULL is a no-op. */
void view_destroy(view_window *v);

/* Handles the window's events (mouse, keys, resize, the close button) and
 * returns false once the window was asked to close. Never blocks. */
bool view_poll(view_window *v);
bool view_should_close(const view_window *v);
/* Sleeps until an event comes or timeout_s passes (a viewer with nothing
 * new to draw); view_poll then handles it. */
void view_wait(view_window *v, double timeout_s);

/* The camera: the free camera's pose is set to T_wc (camera to world, TUM:
 * +z ahead, y down), its pivot pivot_m ahead (> 0), its up the pose's -y. */
void view_set_pose(view_window *v, const bf_se3 *T_wc, double pivot_m);
/* While following, the camera is T_wc (a scan's newest pose); otherwise
 * this only remembers T_wc for when F is pressed. */
void view_follow(view_window *v, const bf_se3 *T_wc);
bool view_is_following(const view_window *v);
/* The pose to ray-cast the next image at. */
bf_se3 view_pose(const view_window *v);
/* The swapchain's size: the ray-cast should have it (a different size is
 * stretched to the window, nearest pixel). */
void view_size(const view_window *v, uint32_t *width, uint32_t *height);

/* What the window says about the scene: its title bar, and the overlay
 * (view_config.overlay) from the next view_show on. */
typedef struct view_status {
    bool has_frame;
    uint32_t frame;       /* frames handled */
    const char *state;    /* tracking state ("tracked", "lost"...), NULL: none */
    uint64_t n_bricks;    /* bricks of the map */
    double map_mib;       /* its memory [MiB], 0: not shown */
} view_status;
void view_set_status(view_window *v, const view_status *st);
/* Turns the overlay on or off (view_config.overlay) from the next view_show. */
void view_set_overlay(view_window *v, bool on);

/* Shows t->colour (width x height, RGBA8) in the window and presents it.
 * With rgb not NULL (3 * width * height of view_size's size), the swapchain
 * image as presented is read back into it as RGB: a screenshot of the
 * window (BF_UNSUPPORTED when the surface cannot be read). A resized or
 * stale swapchain is remade and the frame skipped (*rgb then untouched,
 * BF_OK; *is_shown false). is_shown may be NULL. After a failure the
 * window may hold an image it never presented: detach it (the commands
 * end). */
bf_status view_show(view_window *v, const render_targets *t, uint8_t *rgb, bool *is_shown);

#endif
