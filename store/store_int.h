/* Declarations shared by store/'s files: the on-disk layout
 * (docs/formats.md, "Scene store"). Little-endian throughout. */
#ifndef BF_STORE_INT_H
#define BF_STORE_INT_H

#include "store.h"

#define STORE_INDEX_NAME "store.json"
#define STORE_TRAJ_NAME "trajectory.bin"
#define STORE_CHUNK_DIR "chunks"
#define STORE_FORMAT_NAME "bitfuse-store"

/* Chunk file: a 96-byte header, then the zstd-compressed records. */
#define STORE_CHUNK_MAGIC "BFCHUNK"  /* 8 bytes with its NUL */
#define STORE_CHUNK_HEADER 96u
#define STORE_RECORD_BYTES 136u      /* level, x, y, z (u8 each), error (f32), sign[16], conf[16] (u32) */
/* A chunk with colour: version 2, each record followed by its 512 voxels'
 * RGB565 (u16, voxel x + 8 y + 64 z, 0 = none; hostmap.rgb565). Chunks
 * without a coloured voxel stay version 1, byte for byte. */
#define STORE_CHUNK_VERSION_COLOUR 2u
#define STORE_COLOUR_RECORD_BYTES (STORE_RECORD_BYTES + 1024u)
#define STORE_ZSTD_LEVEL 3

typedef struct store_chunk_header {
    char magic[8];
    uint32_t version;
    uint32_t header_bytes;
    int32_t key[3];
    uint32_t n_bricks;
    float chunk_m;
    uint32_t record_bytes;
    double origin_w[3];
    uint64_t raw_bytes;      /* n_bricks * record_bytes */
    uint64_t payload_bytes;  /* compressed */
    uint64_t payload_hash;   /* XXH3-64 of the compressed payload */
    uint64_t header_hash;    /* XXH3-64 of the 88 bytes before it */
} store_chunk_header;
_Static_assert(sizeof(store_chunk_header) == STORE_CHUNK_HEADER, "chunk header layout");

/* Trajectory file: magic, version, count, then per pose 13 doubles
 * (t, R row-major, t_w), then the XXH3-64 of everything before it. */
#define STORE_TRAJ_MAGIC "BFTRAJ1" /* 8 bytes with its NUL */
#define STORE_TRAJ_HEADER 16u
#define STORE_TRAJ_POSE_DOUBLES 13u

/* Keyframes file: magic, version, count, then per keyframe its pose (12
 * doubles: R row-major, t), its keypoint count n and a zero word, n ORB
 * descriptors of 32 bytes and n points of 3 floats, then the XXH3-64 of
 * everything before it. */
#define STORE_KEYFRAMES_NAME "keyframes.bin"
#define STORE_KEYFRAMES_MAGIC "BFKEYF1" /* 8 bytes with its NUL */
#define STORE_KEYFRAMES_HEADER 16u
#define STORE_KEYFRAME_HEADER 104u /* 12 doubles, n, zero */

/* One chunk's bricks inside a sorted hostmap: [first, first + n). */
typedef struct store_group {
    int32_t key[3];
    uint32_t first, n;
    uint64_t digest;        /* XXH3-64 of its records */
    bool has_colour;        /* a brick of it has a coloured voxel: colour records */
} store_group;

/* Sorts the bricks canonically (key, level, z, y, x). */
void store__sort(hostmap *m);
/* The groups of a sorted map; *out malloc'd (NULL when empty). */
bf_status store__groups(const hostmap *m, store_group **out, uint32_t *n);
/* Writes the records of bricks [first, first + n) into buf (n records of
 * STORE_RECORD_BYTES, or STORE_COLOUR_RECORD_BYTES with_colour). */
void store__pack(const hostmap *m, uint32_t first, uint32_t n, bool with_colour, uint8_t *buf);
static inline size_t store__record_bytes(bool with_colour)
{
    return with_colour ? STORE_COLOUR_RECORD_BYTES : STORE_RECORD_BYTES;
}
/* The chunk file's name for key: "c_X_Y_Z.bfc". */
void store__chunk_name(char *out, size_t cap, const int32_t key[3]);
/* XXH3-64. */
uint64_t store__hash(const void *p, size_t n);
/* Writes path atomically: path.tmp, fsync, rename (the folder's fsync is
 * the caller's). An injected fault (bf_fault_now) fails as ENOSPC. */
bf_status store__write_atomic(const char *path, const void *a, size_t na, const void *b, size_t nb);
/* Files written whole as path.tmp and not yet renamed: a store write puts
 * every new file down first and renames them only when all are whole, so
 * a write that fails (a full disk) leaves the store as the write before. */
typedef struct store_stage {
    char **paths; /* the final names (malloc'd); NAME.tmp is whole on disk */
    int *pending; /* NAME.tmp's bf_pending_add slots, held until the rename */
    uint32_t n, cap;
} store_stage;
/* As store__write_atomic, but path.tmp is added to stage, not renamed. */
bf_status store__write_staged(store_stage *stage, const char *path, const void *a, size_t na, const void *b,
                              size_t nb);
/* Renames every staged file over its final name, in the order staged; the
 * stage is emptied. A failed rename leaves the files before it renamed and
 * removes the rest. */
bf_status store__stage_commit(store_stage *stage);
/* Removes every staged file; the stage is emptied. */
void store__stage_abort(store_stage *stage);
/* keyframes.bin staged (store_keyframes_write writes it at once). */
bf_status store__keyframes_stage(store_stage *stage, const char *dir, const store_keyframes *k);
/* The whole regular file at path into *out (malloc'd, NUL-terminated, *n
 * bytes without the NUL): BF_IO when it cannot be opened or read,
 * BF_FORMAT when it is larger than max. */
bf_status store__read_file(const char *path, size_t max, uint8_t **out, size_t *n);
/* A binary store file (trajectory.bin, keyframes.bin: an 8-byte magic, a
 * u32 version, a u32 count, ..., the XXH3-64 of all before its last 8
 * bytes) read and checked: the magic (what names the kind), the version
 * (BF_UNSUPPORTED when newer) and the checksum (BF_FORMAT). *out
 * (malloc'd), *len and *count written on success. */
bf_status store__read_binary(const char *path, const char *magic, const char *what, size_t max, uint8_t **out,
                             size_t *len, uint32_t *count);

/* A chunk the index lists. */
typedef struct store_entry {
    int32_t key[3];
    uint32_t n_bricks;
    uint64_t digest;        /* XXH3-64 of its records */
    uint64_t file_bytes;
} store_entry;
/* Reads dir/store.json: the meta (frames and pose from the index), its
 * chunks sorted by key (*e malloc'd) and its write count. BF_IO when it is
 * missing, BF_FORMAT when it is malformed, BF_UNSUPPORTED for a newer version. */
bf_status store__index_read(const char *dir, store_meta *meta, store_entry **e, uint32_t *n, uint32_t *flush);
/* Orders entries by key (bsearch / qsort). */
int store__entry_cmp(const void *a, const void *b);

#endif
