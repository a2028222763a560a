/* capture: what the live backends share with the URI dispatch in open.c and
 * with the tests: backend entry points, URI option parsing and the pixel
 * conversions (pure functions, so they are tested without a camera).
 * Private to capture/ and tests/capture/. */
#ifndef BF_CAPTURE_LIVE_INT_H
#define BF_CAPTURE_LIVE_INT_H

#include "capture/capture.h"

/* Wait for a live device's next frame at most this long before calling the
 * device silent: a Kinect or UVC camera at its slowest mode (15 Hz) delivers
 * within 67 ms, so 2 s only fires on a stalled or unplugged device. */
#define CAPTURE_FRAME_TIMEOUT_MS 2000

/* Options after '?' in a URI, "key=value" separated by '&'. Unknown keys
 * are BF_INVALID_ARG naming the URI. has_* say which were given. */
typedef struct capture__uri_options {
    bool has_camera;
    double fx_px, fy_px, cx_px, cy_px;
    bool has_depth_scale;
    double depth_scale;
    char depth_mode[16]; /* freenect's "registered" | "disparity"; "" = default */
} capture__uri_options;

/* Splits "freenect:0?depth=disparity" after the scheme: copies the part
 * before '?' into target (cap bytes) and parses the options. */
bf_status capture__uri_split(const char *uri, const char *after_scheme, char *target, size_t cap,
                             capture__uri_options *opt);
/* Applies camera/depth_scale overrides to a source's intrinsics. */
void capture__apply_options(const capture__uri_options *opt, bf_intrinsics *K);
/* The source capture_paced wraps, NULL for any other (capture_inner). */
const rgbd_source *capture__paced_inner(const rgbd_source *src);

/* ------------------------------------------------------------ backends
 * Each takes the full URI (for messages), the target after the scheme and
 * the options. Only the compiled ones exist: open.c guards by BF_HAVE_*. */

bf_status capture__freenect_open(const char *uri, const char *target, const capture__uri_options *opt,
                                 rgbd_source **out);
uint32_t capture__freenect_list(capture_device_info *out, uint32_t cap);
bf_status capture__openni2_open(const char *uri, const char *target, const capture__uri_options *opt,
                                rgbd_source **out);
uint32_t capture__openni2_list(capture_device_info *out, uint32_t cap);
bf_status capture__v4l2_open(const char *uri, const char *target, const capture__uri_options *opt,
                             rgbd_source **out);
uint32_t capture__v4l2_list(capture_device_info *out, uint32_t cap);

/* ------------------------------------------------------------ Kinect v1 depth */

/* The parameters libfreenect reads from a Kinect v1 to turn its 11-bit
 * disparity into millimetres (freenect_zero_plane_info + const_shift in
 * libfreenect_registration.h). */
typedef struct capture__kinect_params {
    double dcmos_emitter_dist_cm; /* IR camera to IR projector */
    double reference_distance_mm; /* distance of the reference (zero) plane */
    double reference_pixel_size_mm; /* pixel size on the reference plane */
    double const_shift;
} capture__kinect_params;

/* The values libfreenect's registration.c falls back to ("ripped from my
 * Kinect"): 7.5 cm, 120 mm, 0.1042 mm, const_shift 200. */
capture__kinect_params capture__kinect_default_params(void);

/* Raw 11-bit disparity to depth in mm with libfreenect's model
 * (src/registration.c, freenect_raw_to_mm), without its truncation to whole
 * millimetres: NaN for 2047 (no reading) and for values the model maps
 * outside (0, 10 m]. */
double capture__kinect_raw_to_mm(uint16_t raw, const capture__kinect_params *p);

/* Focal length of the IR camera in pixels at 640x480, from the same
 * parameters (libfreenect's freenect_camera_to_world uses
 * 2 * pixel_size / distance per pixel). */
double capture__kinect_ir_focal_px(const capture__kinect_params *p);

/* ------------------------------------------------------------ pixel formats */

/* YUYV (YUY2, V4L2_PIX_FMT_YUYV: Y0 U Y1 V) to RGB8, w must be even;
 * src_stride in bytes. BT.601 limited range, the usual UVC colour space. */
void capture__yuyv_to_rgb(const uint8_t *src, size_t src_stride, uint32_t w, uint32_t h, uint8_t *rgb);
/* UYVY (U Y0 V Y1: OpenNI2's ONI_PIXEL_FORMAT_YUV422, the Kinect's raw
 * YUV) to RGB8, same conventions. */
void capture__uyvy_to_rgb(const uint8_t *src, size_t src_stride, uint32_t w, uint32_t h, uint8_t *rgb);
/* BGR8 to RGB8 (V4L2_PIX_FMT_BGR24). */
void capture__bgr_to_rgb(const uint8_t *src, size_t src_stride, uint32_t w, uint32_t h, uint8_t *rgb);
/* Copies rows of w*bpp bytes from a strided source into a packed buffer. */
void capture__copy_rows(const uint8_t *src, size_t src_stride, size_t row_bytes, uint32_t h, uint8_t *dst);
/* Resize of RGB8 (an unregistered colour image of another size onto the
 * depth grid) that keeps pixel centres: an area average where it shrinks,
 * bilinear where it grows. BF_INVALID_ARG for an empty image, BF_NO_MEMORY
 * for its tap tables. */
bf_status capture__resize_rgb(const uint8_t *src, uint32_t sw, uint32_t sh, uint8_t *dst, uint32_t dw, uint32_t dh);

/* Extends a wrapping 32-bit device counter to 64 bits: keeps the last raw
 * value and the number of wraps. A counter that steps back by more than half
 * its range is taken as a wrap (the Kinect's 60 MHz clock wraps every
 * 71.6 s; frames come every 33 ms). */
typedef struct capture__unwrap32 {
    bool has_last;
    uint32_t last;
    uint64_t high;
} capture__unwrap32;
uint64_t capture__unwrap32_push(capture__unwrap32 *u, uint32_t raw);

/* Focal length in pixels of an image size_px wide (or high) that spans
 * fov_rad: (size/2) / tan(fov/2). NaN for a FOV outside (0, pi). */
double capture__focal_from_fov(uint32_t size_px, double fov_rad);

/* ------------------------------------------------------------ OpenNI2 formats
 * Pure functions over OpenNI2's pixel-format numbers (OniCEnums.h), so the
 * tests need no device. Compiled with the OpenNI2 backend. */

/* Raw units per metre of an OpenNI2 depth format: 1000 for DEPTH_1_MM (100),
 * 10000 for DEPTH_100_UM (101); 0 for the PS1080 shift formats (102, 103),
 * which carry disparity, and anything else. */
double capture__oni_depth_scale(int oni_pixel_format);
/* Converts one OpenNI2 colour frame to RGB8: RGB888 (200), YUV422 (201,
 * UYVY order), YUYV (205), GRAY8 (202). BF_UNSUPPORTED for the rest
 * (JPEG, GRAY16) naming the format. */
bf_status capture__oni_colour_to_rgb(int oni_pixel_format, const uint8_t *src, size_t src_stride, uint32_t w,
                                     uint32_t h, uint8_t *rgb);
/* "DEPTH_1_MM", "RGB888", ... or "format N". */
const char *capture__oni_format_name(int oni_pixel_format);

#endif
