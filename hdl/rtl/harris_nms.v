// ICD steps 4 to 7: candidates, the 3x3 non-maximum suppression with raster-order ties, the
// sub-pixel offsets and the Q12.4 coordinates, one response per clock, with two response rows
// of line buffer.
//
// Input tokens carry r at (x - 3, y - 3) (harris_response.v). Each gives one output token with
// the same coordinates that says whether (x - 4, y - 4) is a feature, and if so its x_q4, y_q4
// and r. The candidate border (ICD step 4) is 4 <= x - 4 <= W - 5, 4 <= y - 4 <= H - 5, that is
// x >= 8 and y >= 8 (the upper bounds hold for every token); the 3x3 neighbourhood of such a
// pixel has responses that the ICD defines, and only those are compared. Latency 7 clocks.
`default_nettype none
module harris_nms #(
    parameter integer MAX_WIDTH = 4095
) (
    input  wire               clk,
    input  wire               rst,
    input  wire signed [31:0] threshold,
    input  wire               in_valid,
    input  wire [11:0]        in_x,
    input  wire [11:0]        in_y,
    input  wire signed [31:0] in_r,
    output reg                out_valid,
    output reg  [11:0]        out_x,
    output reg  [11:0]        out_y,
    output reg                out_feature,
    output reg  [15:0]        out_x_q4,
    output reg  [15:0]        out_y_q4,
    output reg  signed [31:0] out_r
);
`include "harris_consts.vh"
    localparam integer ADDR_BITS = $clog2(MAX_WIDTH);
    // The first input coordinate whose feature position is inside the candidate border.
    localparam integer FIRST_CANDIDATE = CANDIDATE_BORDER + LAG;           // 8

    // Stage 1: the response waits one clock for the line buffer's read of its column.
    reg               v1;
    reg [11:0]        x1, y1;
    reg signed [31:0] r1;
    // Response rows y - 2 (high) and y - 1 (low) at each column.
    wire [2*RESPONSE_BITS-1:0] above;
    sdp_ram #(.WIDTH(2 * RESPONSE_BITS), .DEPTH(MAX_WIDTH), .ADDR_BITS(ADDR_BITS)) rows (
        .clk(clk),
        // Written one clock after its read, as in harris_sobel.v.
        .we(v1), .waddr(x1[ADDR_BITS-1:0]), .wdata({above[RESPONSE_BITS-1:0], r1}),
        .raddr(in_x[ADDR_BITS-1:0]), .rdata(above)
    );

    // Stage 2: the 3x3 window of responses: columns right (x + 1), centre, left (x - 1) of the
    // pixel tested; rows up (y - 1), mid, down (y + 1). It moves only when a token arrives.
    reg               v2;
    reg [11:0]        x2, y2;
    reg signed [31:0] up_l, up_c, up_r, mid_l, mid_c, mid_r, down_l, down_c, down_r;

    // ICD step 5: strictly above the neighbours before it in raster order, at least the ones
    // after it.
    wire is_candidate = mid_c > threshold;
    wire wins_before = (mid_c > up_l) && (mid_c > up_c) && (mid_c > up_r) && (mid_c > mid_l);
    wire wins_after = (mid_c >= mid_r) && (mid_c >= down_l) && (mid_c >= down_c)
                      && (mid_c >= down_r);
    wire in_border = (x2 >= FIRST_CANDIDATE) && (y2 >= FIRST_CANDIDATE);

    // Stage 3: the decision, and the sub-pixel numerators and denominators (ICD step 6):
    // ox = trunc(16 num / den) with num = r(x-1) - r(x+1), den = 2 (r(x-1) - 2 r + r(x+1)),
    // that is trunc(8 num / half) with half = den / 2, the same quotient. |num| <= 2^32 (33-bit
    // signed), |half| <= 2^33 (35-bit signed).
    reg               v3, feature3;
    reg [11:0]        x3, y3;
    reg signed [31:0] r3;
    reg signed [32:0] num_x3, num_y3;
    reg signed [34:0] half_x3, half_y3;

    // Stages 4 to 6: the offsets (harris_subpixel.v), one per axis, latency 3.
    wire signed [OFFSET_BITS-1:0] ox, oy;
    harris_subpixel sub_x (.clk(clk), .num(num_x3), .half(half_x3), .offset(ox));
    harris_subpixel sub_y (.clk(clk), .num(num_y3), .half(half_y3), .offset(oy));
    reg               v4, v5, v6, feature4, feature5, feature6;
    reg [11:0]        x4, y4, x5, y5, x6, y6;
    reg signed [31:0] r4, r5, r6;

    // ICD step 7: x_q4 = 16 (x - 4) + ox. The feature's column is at most 4090 and |ox| <= 8, so
    // the 16-bit sum never wraps for a feature.
    wire [15:0] x_base = {x6 - LAG[11:0], {Q4_SHIFT{1'b0}}};
    wire [15:0] y_base = {y6 - LAG[11:0], {Q4_SHIFT{1'b0}}};

    always @(posedge clk) begin
        v1 <= in_valid;
        x1 <= in_x;
        y1 <= in_y;
        r1 <= in_r;

        v2 <= v1;
        x2 <= x1;
        y2 <= y1;
        if (v1) begin
            {up_l, mid_l, down_l} <= {up_c, mid_c, down_c};
            {up_c, mid_c, down_c} <= {up_r, mid_r, down_r};
            {up_r, mid_r, down_r} <= {above[2*RESPONSE_BITS-1:RESPONSE_BITS],
                                      above[RESPONSE_BITS-1:0], r1};
        end

        v3 <= v2;
        x3 <= x2;
        y3 <= y2;
        r3 <= mid_c;
        feature3 <= is_candidate && wins_before && wins_after && in_border;
        num_x3 <= {mid_l[31], mid_l} - {mid_r[31], mid_r};
        num_y3 <= {up_c[31], up_c} - {down_c[31], down_c};
        half_x3 <= {{3{mid_l[31]}}, mid_l} - {{2{mid_c[31]}}, mid_c, 1'b0} + {{3{mid_r[31]}}, mid_r};
        half_y3 <= {{3{up_c[31]}}, up_c} - {{2{mid_c[31]}}, mid_c, 1'b0} + {{3{down_c[31]}}, down_c};

        {v4, x4, y4, r4, feature4} <= {v3, x3, y3, r3, feature3};
        {v5, x5, y5, r5, feature5} <= {v4, x4, y4, r4, feature4};
        {v6, x6, y6, r6, feature6} <= {v5, x5, y5, r5, feature5};

        out_valid <= v6;
        out_x <= x6;
        out_y <= y6;
        out_feature <= v6 && feature6;
        out_r <= r6;
        out_x_q4 <= x_base + {{(16 - OFFSET_BITS){ox[OFFSET_BITS-1]}}, ox};
        out_y_q4 <= y_base + {{(16 - OFFSET_BITS){oy[OFFSET_BITS-1]}}, oy};
        // Only the valid bits are reset: a token's data is never used without its valid bit.
        if (rst) begin
            v1 <= 1'b0;
            v2 <= 1'b0;
            v3 <= 1'b0;
            v4 <= 1'b0;
            v5 <= 1'b0;
            v6 <= 1'b0;
            out_valid <= 1'b0;
        end
    end
endmodule
`default_nettype wire
