// ICD step 6: one axis's sub-pixel offset in 1/16 pixel, ox = trunc(16 num / den) clamped to
// [-8, 8], 0 when den = 0, given num and half = den / 2 (so ox = trunc(8 num / half)).
//
// The quotient's magnitude is q = min(8, floor(8 |num| / |half|)) and its sign that of
// num * half (truncation toward zero rounds the magnitude down). q >= 8 exactly when
// |num| >= |half|; below that, three steps of restoring division give its bits. Latency 3.
`default_nettype none
module harris_subpixel (
    input  wire               clk,
    input  wire signed [32:0] num,
    input  wire signed [34:0] half,
    output reg  signed [4:0]  offset
);
`include "harris_consts.vh"
    // |num| <= 2^32, |half| <= 2^33; the partial remainders below are < 8 |half| < 2^37.
    wire [32:0] num_abs = num[32] ? -num : num;
    wire [34:0] half_abs = half[34] ? -half : half;

    // Stage 1: clamp test and the quotient's bit 2 (8 |num| >= 4 |half|).
    reg         negative1, zero1, clamp1, q2_1;
    reg [37:0]  rem1;
    reg [34:0]  div1;
    wire [37:0] dividend = {2'b0, num_abs, 3'b0};                          // 8 |num|
    wire [37:0] four_half = {1'b0, half_abs, 2'b0};
    // Stage 2: bit 1.
    reg         negative2, zero2, clamp2, q2_2, q1_2;
    reg [37:0]  rem2;
    reg [34:0]  div2;
    wire [37:0] two_half1 = {2'b0, div1, 1'b0};

    wire [3:0]  q3 = {1'b0, q2_2, q1_2, rem2 >= {3'b0, div2}};
    wire [3:0]  magnitude = clamp2 ? SUBPIXEL_CLAMP[3:0] : q3;

    always @(posedge clk) begin
        negative1 <= num[32] ^ half[34];
        zero1 <= half == 0;
        clamp1 <= {2'b0, num_abs} >= half_abs;
        q2_1 <= dividend >= four_half;
        rem1 <= dividend >= four_half ? dividend - four_half : dividend;
        div1 <= half_abs;

        negative2 <= negative1;
        zero2 <= zero1;
        clamp2 <= clamp1;
        q2_2 <= q2_1;
        q1_2 <= rem1 >= two_half1;
        rem2 <= rem1 >= two_half1 ? rem1 - two_half1 : rem1;
        div2 <= div1;

        if (zero2) begin
            offset <= 0;
        end else if (negative2) begin
            offset <= -$signed({1'b0, magnitude});
        end else begin
            offset <= $signed({1'b0, magnitude});
        end
    end
endmodule
`default_nettype wire
