/* Fuzz target: the folder sequences through replay_open and the frame
 * reader, every frame read to the end: TUM RGB-D, ICL-NUIM and pose-per-
 * frame folders.
 *
 * The input is FUZZ_SEP-separated parts. Part 0 is a line of words: the
 * layout ("tum", "icl" or "pose") and options ("skip": --skip-bad-frames,
 * "max2": --frames 2, "scale": --depth-scale 1000). The other parts are the
 * folder's files; a part that is empty or that the input does not have is
 * a file that is absent:
 *   tum:  rgb.txt, depth.txt, groundtruth.txt, camera.txt, the depth image
 *         (written as depth/d.png) and the colour image (rgb/c.png, also
 *         rgb/c.jpg), which the lists may name;
 *   icl:  pose.txt, camera.txt, the depth image (depth/0.png and
 *         depth/1.png), the colour image (color/0.png, color/1.jpg);
 *   pose: camera-intrinsics.txt, frame-000000.pose.txt,
 *         frame-000001.pose.txt, the depth image (frame-00000{0,1}.depth.png),
 *         the colour image (frame-00000{0,1}.color.jpg). */
#include <string.h>

#include "fuzz.h"
#include "replay/replay.h"

#define FOLDER_PARTS 7

typedef struct folder_file {
    int part;
    const char *name;
} folder_file;

static const folder_file tum_files[] = {
    {1, "rgb.txt"}, {2, "depth.txt"}, {3, "groundtruth.txt"}, {4, "camera.txt"},
    {5, "depth/d.png"}, {6, "rgb/c.png"}, {6, "rgb/c.jpg"}, {0, NULL},
};
static const folder_file icl_files[] = {
    {1, "pose.txt"}, {2, "camera.txt"}, {3, "depth/0.png"}, {3, "depth/1.png"},
    {4, "color/0.png"}, {4, "color/1.jpg"}, {0, NULL},
};
static const folder_file pose_files[] = {
    {1, "camera-intrinsics.txt"}, {2, "frame-000000.pose.txt"}, {3, "frame-000001.pose.txt"},
    {4, "frame-000000.depth.png"}, {4, "frame-000001.depth.png"}, {5, "frame-000000.color.jpg"},
    {5, "frame-000001.color.jpg"}, {0, NULL},
};

static bool has_word(const fuzz_part *p, const char *w)
{
    size_t n = strlen(w);
    for (size_t i = 0; i + n <= p->n; i++)
        if (memcmp(p->p + i, w, n) == 0) return true;
    return false;
}

bf_status fuzz_folder(const uint8_t *data, size_t size)
{
    fuzz_part parts[FOLDER_PARTS];
    int n = fuzz_split(data, size, parts, FOLDER_PARTS);
    const folder_file *files = has_word(&parts[0], "icl")    ? icl_files
                               : has_word(&parts[0], "pose") ? pose_files
                                                             : tum_files;
    replay_options opt = {
        .skip_bad_frames = has_word(&parts[0], "skip"),
        .max_frames = has_word(&parts[0], "max2") ? 2 : 0,
        .depth_scale = has_word(&parts[0], "scale") ? 1000 : 0,
    };
    const char *dir = fuzz_scratch();
    for (const folder_file *f = files; f->name; f++)
        if (f->part < n && parts[f->part].n && !fuzz_write(dir, f->name, parts[f->part].p, parts[f->part].n)) return BF_IO;
    rgbd_source *src = NULL;
    bf_status s = replay_open(dir, &opt, &src);
    if (s != BF_OK) return s;
    bf_frame frame;
    while ((s = rgbd_source_next(src, &frame)) == BF_OK) fuzz_touch_frame(&frame);
    rgbd_source_close(src);
    return s == BF_END ? BF_OK : s;
}

FUZZ_TARGET(fuzz_folder)
