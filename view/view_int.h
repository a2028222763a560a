/* Declarations shared by view/'s files. Not for other modules. */
#ifndef BF_VIEW_INT_H
#define BF_VIEW_INT_H

#include "view/view.h"

/* The free camera: a pose, the distance of the pivot ahead of it, and the
 * world's up (orbits turn about it). Pure functions (camera.c). */
typedef struct view__camera {
    bf_se3 T_wc;
    double pivot_m;
    bf_vec3 up_w;
} view__camera;

view__camera view__camera_make(const bf_se3 *T_wc, double pivot_m);
/* Turns about the pivot: yaw about up_w, then pitch about the camera's x. */
void view__camera_orbit(view__camera *c, double yaw_rad, double pitch_rad);
/* Moves the camera in its image plane by (dx, dy) pixels at the pivot's
 * depth with focal length f_px, so the pivot's plane follows the cursor. */
void view__camera_pan(view__camera *c, double dx_px, double dy_px, double f_px);
/* Moves towards the pivot: notches > 0 closer, by fraction per notch of the distance. */
void view__camera_zoom(view__camera *c, double notches, double fraction);

/* The 3x5 glyph of ch for the overlay (shaders/view.glsl.h's layout);
 * unknown characters get a question mark (font.c). */
uint32_t view__glyph(char ch);

#endif
