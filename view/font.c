/* A 3x5 pixel font for the status overlay: digits, letters (capitals for
 * both cases) and the punctuation a status line needs. Drawn for this
 * project in the manner of the common 3x5 "tom thumb" style pixel fonts;
 * each row lists its three pixels, left = 4, middle = 2, right = 1. */
#include <ctype.h>

#include "view_int.h"

#define G(a, b, c, d, e) ((uint32_t)(a) | (uint32_t)(b) << 3 | (uint32_t)(c) << 6 | (uint32_t)(d) << 9 | (uint32_t)(e) << 12)

static const uint32_t digits[10] = {
    G(7, 5, 5, 5, 7), G(2, 6, 2, 2, 7), G(7, 1, 7, 4, 7), G(7, 1, 7, 1, 7), G(5, 5, 7, 1, 1),
    G(7, 4, 7, 1, 7), G(7, 4, 7, 5, 7), G(7, 1, 1, 1, 1), G(7, 5, 7, 5, 7), G(7, 5, 7, 1, 7),
};

static const uint32_t letters[26] = {
    G(2, 5, 7, 5, 5), G(6, 5, 6, 5, 6), G(3, 4, 4, 4, 3), G(6, 5, 5, 5, 6), G(7, 4, 6, 4, 7), /* A-E */
    G(7, 4, 6, 4, 4), G(3, 4, 5, 5, 3), G(5, 5, 7, 5, 5), G(7, 2, 2, 2, 7), G(1, 1, 1, 5, 2), /* F-J */
    G(5, 5, 6, 5, 5), G(4, 4, 4, 4, 7), G(5, 7, 7, 5, 5), G(6, 5, 5, 5, 5), G(2, 5, 5, 5, 2), /* K-O */
    G(6, 5, 6, 4, 4), G(2, 5, 5, 6, 3), G(6, 5, 6, 5, 5), G(3, 4, 2, 1, 6), G(7, 2, 2, 2, 2), /* P-T */
    G(5, 5, 5, 5, 7), G(5, 5, 5, 5, 2), G(5, 5, 7, 7, 5), G(5, 5, 2, 5, 5), G(5, 5, 2, 2, 2), /* U-Y */
    G(7, 1, 2, 4, 7),                                                                         /* Z */
};

uint32_t view__glyph(char ch)
{
    unsigned char c = (unsigned char)ch;
    if (c >= '0' && c <= '9') return digits[c - '0'];
    if (isalpha(c)) return letters[toupper(c) - 'A'];
    switch (c) {
    case ' ': return 0;
    case '.': return G(0, 0, 0, 0, 2);
    case ',': return G(0, 0, 0, 2, 4);
    case ':': return G(0, 2, 0, 2, 0);
    case '|': return G(2, 2, 2, 2, 2);
    case '(': return G(1, 2, 2, 2, 1);
    case ')': return G(4, 2, 2, 2, 4);
    case '-': return G(0, 0, 7, 0, 0);
    case '+': return G(0, 2, 7, 2, 0);
    case '/': return G(1, 1, 2, 4, 4);
    case '%': return G(5, 1, 2, 4, 5);
    case '=': return G(0, 7, 0, 7, 0);
    case '_': return G(0, 0, 0, 0, 7);
    default: return G(7, 1, 2, 0, 2); /* '?' */
    }
}
