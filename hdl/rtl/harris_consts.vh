// The board's named widths and constants (board-icd.md sections 1 and 2), included inside the
// modules that use them. Every shift and width of the arithmetic is here, with the ICD step it
// comes from; the modules use no other magic numbers.

// ICD section 1: WIDTH and HEIGHT are 16..=4095, so a coordinate fits in 12 bits.
localparam integer COORD_BITS = 12;
localparam integer MIN_SIZE = 16;
localparam integer MAX_SIZE = 4095;
// ICD section 1: MAX_FEATURES is 1..=1023 (also the wire format's count limit): 10 bits.
localparam integer COUNT_BITS = 10;
localparam integer MAX_FEATURES_LIMIT = 1023;
// ICD section 1: THRESHOLD is any signed 32-bit value; r is signed 32-bit (ICD step 3).
localparam integer RESPONSE_BITS = 32;
// 8-bit sensors (ICD section 1).
localparam integer PIXEL_BITS = 8;

// ICD step 1: |gx|, |gy| <= 4 * 255 = 1020, 11-bit signed.
localparam integer GRAD_BITS = 11;
// gx^2 <= 1,040,400 < 2^20 (unsigned); |gx gy| <= 1,040,400, 21-bit signed.
localparam integer SQUARE_BITS = 20;
localparam integer CROSS_BITS = 21;
// ICD step 2: the 5x5 window, WINDOW_RADIUS = 2.
localparam integer WINDOW_RADIUS = 2;
localparam integer WINDOW_ROWS = 2 * WINDOW_RADIUS + 1;
// A column of the window (five rows): sum of squares <= 5,202,000 < 2^23; the cross sum is
// within +-5,202,000, 24-bit signed.
localparam integer COL_SQUARE_BITS = 23;
localparam integer COL_CROSS_BITS = 24;
// ICD step 2: Sxx, Syy <= 26,010,000 < 2^25. Sxy is bounded here by 25 * 1020^2 = 26,010,000
// (not by the ICD's tighter 14,630,625 for images), so 26-bit signed; |Sxy| fits in 25 bits.
localparam integer SUM_SQUARE_BITS = 25;
localparam integer SUM_CROSS_BITS = 26;
// ICD step 3: T = Sxx + Syy <= 52,020,000 < 2^26.
localparam integer TRACE_BITS = 26;
// ICD step 3: k = K_NUMERATOR / 2^K_SHIFT = 41 / 1024, r = Rs >> RESPONSE_SHIFT.
localparam integer K_NUMERATOR = 41;
localparam integer K_SHIFT = 10;
localparam integer RESPONSE_SHIFT = 27;
// Rs is computed modulo 2^RS_BITS: r is bits 27..58 of Rs, which is all that is kept, and bits
// 0..58 of a sum, difference or product depend only on bits 0..58 of its operands. This is
// harris-core's `response` exactly (it takes the same bits of the 64-bit two's complement).
localparam integer RS_BITS = RESPONSE_SHIFT + RESPONSE_BITS;            // 59
localparam integer DET_BITS = RS_BITS - K_SHIFT;                       // 49: det << 10 mod 2^59
// Products of window sums: Sxx Syy and |Sxy|^2 < 2^50, T^2 < 2^52.
localparam integer PRODUCT_BITS = 2 * SUM_SQUARE_BITS;                 // 50
localparam integer TRACE_SQUARE_BITS = 2 * TRACE_BITS;                 // 52

// ICD step 4: no candidate closer than CANDIDATE_BORDER pixels to an image edge.
localparam integer CANDIDATE_BORDER = 4;
// ICD step 6: sub-pixel offsets in 1/SUBPIXEL_SCALE pixel, clamped to +-SUBPIXEL_CLAMP.
localparam integer SUBPIXEL_SCALE = 16;
localparam integer SUBPIXEL_CLAMP = 8;
localparam integer OFFSET_BITS = 5;                                    // -8..=8
// ICD step 7: x_q4 = (x << Q4_SHIFT) + ox, unsigned 16-bit.
localparam integer Q4_SHIFT = 4;
localparam integer Q4_BITS = 16;

// The pipeline's lag: the suppression of pixel (x, y) is decided when pixel (x + LAG, y + LAG)
// arrives: one column/row for the 3x3 Sobel, WINDOW_RADIUS for the window, one for the 3x3
// suppression. Tokens carry the coordinates of the input pixel that produced them.
localparam integer SOBEL_LAG = 1;
localparam integer WINDOW_LAG = SOBEL_LAG + WINDOW_RADIUS;              // 3: response of (x-3, y-3)
localparam integer LAG = WINDOW_LAG + 1;                                // 4: feature at (x-4, y-4)
