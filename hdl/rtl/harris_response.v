// ICD step 3: the Harris response r = ((Sxx Syy - Sxy^2) << 10) - 41 (Sxx + Syy)^2) >> 27,
// fully pipelined, one window per clock.
//
// Rs is computed modulo 2^59 (RS_BITS) and r is its bits 27..58: for every window an 8-bit image
// gives, Rs fits in 59 signed bits and r in 32 (the ICD's claim), so this is the arithmetic
// shift of the exact Rs; for any other input it is what harris-core's `response` gives (bits
// 27..58 of the 64-bit two's complement). det uses |Sxy|, so all three products are unsigned.
// Latency 4 clocks. The tag (coordinates) passes through unchanged.
`default_nettype none
module harris_response #(
    parameter integer TAG_BITS = 24
) (
    input  wire                clk,
    input  wire                rst,
    input  wire                in_valid,
    input  wire [TAG_BITS-1:0] in_tag,
    input  wire [24:0]         in_sxx,
    input  wire [24:0]         in_syy,
    input  wire signed [25:0]  in_sxy,
    output reg                 out_valid,
    output reg  [TAG_BITS-1:0] out_tag,
    output reg  signed [31:0]  out_r
);
`include "harris_consts.vh"

    // Stage 1: the trace and |Sxy| (multiplier inputs registered).
    reg                          v1;
    reg [TAG_BITS-1:0]           t1;
    reg [SUM_SQUARE_BITS-1:0]    sxx1, syy1, sxy_abs1;
    reg [TRACE_BITS-1:0]         trace1;
    // Stage 2: the three products.
    reg                          v2;
    reg [TAG_BITS-1:0]           t2;
    reg [PRODUCT_BITS-1:0]       sxx_syy2, sxy_sq2;
    reg [TRACE_SQUARE_BITS-1:0]  trace_sq2;
    // Stage 3: det and k T^2 (41 T^2 = 32 T^2 + 8 T^2 + T^2), modulo 2^59.
    reg                          v3;
    reg [TAG_BITS-1:0]           t3;
    reg [DET_BITS-1:0]           det3;
    reg [RS_BITS-1:0]            k_trace_sq3;

    // |Sxy| <= 26,010,000 < 2^25 (harris_consts.vh).
    wire [SUM_CROSS_BITS-1:0] sxy_abs = in_sxy[SUM_CROSS_BITS-1] ? -in_sxy : in_sxy;
    wire [PRODUCT_BITS-1:0]   det_full = sxx_syy2 - sxy_sq2;
    wire [RS_BITS-1:0]        trace_sq_wide = {{(RS_BITS - TRACE_SQUARE_BITS){1'b0}}, trace_sq2};
    wire [RS_BITS-1:0]        rs = {det3, {K_SHIFT{1'b0}}} - k_trace_sq3;

    always @(posedge clk) begin
        v1 <= in_valid;
        t1 <= in_tag;
        sxx1 <= in_sxx;
        syy1 <= in_syy;
        sxy_abs1 <= sxy_abs[SUM_SQUARE_BITS-1:0];
        trace1 <= {1'b0, in_sxx} + {1'b0, in_syy};

        v2 <= v1;
        t2 <= t1;
        sxx_syy2 <= sxx1 * syy1;
        sxy_sq2 <= sxy_abs1 * sxy_abs1;
        trace_sq2 <= trace1 * trace1;

        v3 <= v2;
        t3 <= t2;
        // det >= 0 for every image (Cauchy-Schwarz); only its low 49 bits reach Rs mod 2^59.
        det3 <= det_full[DET_BITS-1:0];
        // K_NUMERATOR = 41 = 0b101001.
        k_trace_sq3 <= (trace_sq_wide << 5) + (trace_sq_wide << 3) + trace_sq_wide;

        out_valid <= v3;
        out_tag <= t3;
        out_r <= rs[RS_BITS-1:RESPONSE_SHIFT];
        // Only the valid bits are reset: a token's data is never used without its valid bit.
        if (rst) begin
            v1 <= 1'b0;
            v2 <= 1'b0;
            v3 <= 1'b0;
            out_valid <= 1'b0;
        end
    end
endmodule
`default_nettype wire
