/* The chunk lookup (DESIGN.md section 3; Niessner et al. 2013), one body
 * for the shaders that find chunks (fusion_alloc.comp, render_raycast.comp)
 * and for the host (fusion_check, the tests' host inserter): a bucket's
 * FUSION_BUCKET_SLOTS slots first, then the overflow chain linked from its
 * last slot. A chain holds at most n_overflow entries, so a lookup follows
 * at most that many links (a corrupt link cannot make it loop).
 *
 * The hash's words come through an accessor, since a GLSL function cannot
 * take a buffer: a shader defines `uint fusion_hash_word(uint i)` (word i of
 * its hash buffer) before including this header; C passes the words as the
 * first argument (FUSION_HASH_IN). The functions are otherwise pure. */
#ifndef BF_FUSION_HASH_GLSL_H
#define BF_FUSION_HASH_GLSL_H

#include "fusion.glsl.h"

#ifdef BF_GLSL
#  define FUSION_HASH_IN
#  define FUSION_HASH_ARG
#  define FUSION_HASH_WORD(i) fusion_hash_word(i)
#else
#  define FUSION_HASH_IN const bf_u32 *hash_words,
#  define FUSION_HASH_ARG hash_words,
#  define FUSION_HASH_WORD(i) hash_words[i]
#endif

/* Whether hash entry e holds chunk (x, y, z) (its state is read first: an
 * inserter writes it last). One boolean expression: llvmpipe runs an
 * early-return form of it measurably slower in the ray-cast
 * (docs/bench_replay.md). */
BF_FN bool fusion_entry_holds(FUSION_HASH_IN bf_u32 e, bf_i32 x, bf_i32 y, bf_i32 z)
{
    bf_u32 base = e * FUSION_ENTRY_WORDS;
    return FUSION_HASH_WORD(base + FUSION_ENTRY_STATE) == FUSION_ENTRY_VALID &&
           BF_I32(FUSION_HASH_WORD(base + FUSION_ENTRY_X)) == x && BF_I32(FUSION_HASH_WORD(base + FUSION_ENTRY_Y)) == y &&
           BF_I32(FUSION_HASH_WORD(base + FUSION_ENTRY_Z)) == z;
}

/* Hash entry of chunk (x, y, z) in its bucket (fusion_hash), FUSION_NONE if
 * absent. */
BF_FN bf_u32 fusion_find_in_bucket(FUSION_HASH_IN bf_u32 bucket, bf_i32 x, bf_i32 y, bf_i32 z, bf_u32 n_overflow)
{
    bf_u32 first = bucket * FUSION_BUCKET_SLOTS;
    for (bf_u32 k = 0u; k < FUSION_BUCKET_SLOTS; k++)
        if (fusion_entry_holds(FUSION_HASH_ARG first + k, x, y, z)) return first + k;
    bf_u32 e = FUSION_HASH_WORD((first + FUSION_BUCKET_SLOTS - 1u) * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT);
    for (bf_u32 guard = 0u; e != FUSION_NONE && guard < n_overflow; guard++) {
        if (fusion_entry_holds(FUSION_HASH_ARG e, x, y, z)) return e;
        e = FUSION_HASH_WORD(e * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT);
    }
    return FUSION_NONE;
}

/* Hash entry of chunk (x, y, z), FUSION_NONE if absent. */
BF_FN bf_u32 fusion_find_chunk(FUSION_HASH_IN bf_i32 x, bf_i32 y, bf_i32 z, bf_u32 n_buckets, bf_u32 n_overflow)
{
    return fusion_find_in_bucket(FUSION_HASH_ARG fusion_hash(x, y, z, n_buckets), x, y, z, n_overflow);
}

#endif
