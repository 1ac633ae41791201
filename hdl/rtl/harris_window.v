// ICD step 2: the structure tensor's 5x5 window sums Sxx = sum gx^2, Syy = sum gy^2,
// Sxy = sum gx gy, one gradient per clock, with four gradient rows of line buffer.
//
// Input tokens carry the gradient at (x - 1, y - 1) (harris_sobel.v). Each gives one output
// token with the same coordinates carrying the sums of the window centred on (x - 3, y - 3),
// over gradient rows y - 5 ..= y - 1 and columns x - 5 ..= x - 1. They are exact where the ICD
// defines them (3 <= x - 3 <= W - 4, 3 <= y - 3 <= H - 4); elsewhere meaningless and unused.
// The column of five products is summed first (vertical), then five columns (horizontal).
// Latency 8 clocks. Fifteen 11x11 multipliers (three products for each of the five rows).
`default_nettype none
module harris_window #(
    parameter integer MAX_WIDTH = 4095
) (
    input  wire               clk,
    input  wire               rst,
    input  wire               in_valid,
    input  wire [11:0]        in_x,
    input  wire [11:0]        in_y,
    input  wire signed [10:0] in_gx,
    input  wire signed [10:0] in_gy,
    output reg                out_valid,
    output reg  [11:0]        out_x,
    output reg  [11:0]        out_y,
    output reg  [24:0]        out_sxx,
    output reg  [24:0]        out_syy,
    output reg  signed [25:0] out_sxy
);
`include "harris_consts.vh"
    localparam integer ADDR_BITS = $clog2(MAX_WIDTH);
    localparam integer PAIR_BITS = 2 * GRAD_BITS;                          // {gx, gy}
    localparam integer HELD_ROWS = WINDOW_ROWS - 1;                        // 4 rows buffered

    // Stage 1: the gradient waits one clock for the line buffer's read of its column.
    reg                          v1;
    reg [11:0]                   x1, y1;
    reg [PAIR_BITS-1:0]          g1;
    // Rows y - 4 (high) .. y - 1 (low) of {gx, gy} at each column.
    wire [HELD_ROWS*PAIR_BITS-1:0] above;
    sdp_ram #(.WIDTH(HELD_ROWS * PAIR_BITS), .DEPTH(MAX_WIDTH), .ADDR_BITS(ADDR_BITS)) rows (
        .clk(clk),
        // Written one clock after its read, as in harris_sobel.v.
        .we(v1), .waddr(x1[ADDR_BITS-1:0]),
        .wdata({above[(HELD_ROWS-1)*PAIR_BITS-1:0], g1}),
        .raddr(in_x[ADDR_BITS-1:0]), .rdata(above)
    );

    // Stage 2: the column of five gradients, oldest row first.
    reg                 v2;
    reg [11:0]          x2, y2;
    reg signed [10:0]   gx2 [0:WINDOW_ROWS-1];
    reg signed [10:0]   gy2 [0:WINDOW_ROWS-1];
    // Stage 3: the fifteen products.
    reg                 v3;
    reg [11:0]          x3, y3;
    reg [19:0]          xx3 [0:WINDOW_ROWS-1];
    reg [19:0]          yy3 [0:WINDOW_ROWS-1];
    reg signed [20:0]   xy3 [0:WINDOW_ROWS-1];
    // Stages 4 and 5: the column sums, in two adder levels.
    reg                 v4, v5;
    reg [11:0]          x4, y4, x5, y5;
    reg [21:0]          xx4a, xx4b, yy4a, yy4b;
    reg [19:0]          xx4c, yy4c;
    reg signed [22:0]   xy4a, xy4b;
    reg signed [20:0]   xy4c;
    reg [22:0]          col_xx5, col_yy5;
    reg signed [23:0]   col_xy5;
    // Stage 6: the last five column sums (h[0] the newest), moved only by a valid token.
    reg                 v6;
    reg [11:0]          x6, y6;
    reg [22:0]          h_xx [0:WINDOW_ROWS-1];
    reg [22:0]          h_yy [0:WINDOW_ROWS-1];
    reg signed [23:0]   h_xy [0:WINDOW_ROWS-1];
    // Stage 7: the window sums, first adder level.
    reg                 v7;
    reg [11:0]          x7, y7;
    reg [23:0]          xx7a, xx7b, yy7a, yy7b;
    reg [22:0]          xx7c, yy7c;
    reg signed [24:0]   xy7a, xy7b;
    reg signed [23:0]   xy7c;

    integer i;
    always @(posedge clk) begin
        v1 <= in_valid;
        x1 <= in_x;
        y1 <= in_y;
        g1 <= {in_gx, in_gy};

        v2 <= v1;
        x2 <= x1;
        y2 <= y1;
        for (i = 0; i < HELD_ROWS; i = i + 1) begin
            {gx2[i], gy2[i]} <= above[(HELD_ROWS-i)*PAIR_BITS-1 -: PAIR_BITS];
        end
        {gx2[HELD_ROWS], gy2[HELD_ROWS]} <= g1;

        v3 <= v2;
        x3 <= x2;
        y3 <= y2;
        for (i = 0; i < WINDOW_ROWS; i = i + 1) begin
            // Squares are never negative and at most 1020^2 < 2^20: the low 20 bits of the
            // 22-bit signed product are its value.
            xx3[i] <= square(gx2[i]);
            yy3[i] <= square(gy2[i]);
            xy3[i] <= cross_product(gx2[i], gy2[i]);
        end

        v4 <= v3;
        x4 <= x3;
        y4 <= y3;
        xx4a <= xx3[0] + xx3[1];
        xx4b <= xx3[2] + xx3[3];
        xx4c <= xx3[4];
        yy4a <= yy3[0] + yy3[1];
        yy4b <= yy3[2] + yy3[3];
        yy4c <= yy3[4];
        xy4a <= xy3[0] + xy3[1];
        xy4b <= xy3[2] + xy3[3];
        xy4c <= xy3[4];

        v5 <= v4;
        x5 <= x4;
        y5 <= y4;
        col_xx5 <= xx4a + xx4b + xx4c;
        col_yy5 <= yy4a + yy4b + yy4c;
        col_xy5 <= xy4a + xy4b + xy4c;

        v6 <= v5;
        x6 <= x5;
        y6 <= y5;
        if (v5) begin
            for (i = WINDOW_ROWS - 1; i > 0; i = i - 1) begin
                h_xx[i] <= h_xx[i-1];
                h_yy[i] <= h_yy[i-1];
                h_xy[i] <= h_xy[i-1];
            end
            h_xx[0] <= col_xx5;
            h_yy[0] <= col_yy5;
            h_xy[0] <= col_xy5;
        end

        v7 <= v6;
        x7 <= x6;
        y7 <= y6;
        xx7a <= h_xx[0] + h_xx[1];
        xx7b <= h_xx[2] + h_xx[3];
        xx7c <= h_xx[4];
        yy7a <= h_yy[0] + h_yy[1];
        yy7b <= h_yy[2] + h_yy[3];
        yy7c <= h_yy[4];
        xy7a <= h_xy[0] + h_xy[1];
        xy7b <= h_xy[2] + h_xy[3];
        xy7c <= h_xy[4];

        out_valid <= v7;
        out_x <= x7;
        out_y <= y7;
        out_sxx <= xx7a + xx7b + xx7c;
        out_syy <= yy7a + yy7b + yy7c;
        out_sxy <= xy7a + xy7b + xy7c;
        // Only the valid bits are reset: a token's data is never used without its valid bit.
        if (rst) begin
            v1 <= 1'b0;
            v2 <= 1'b0;
            v3 <= 1'b0;
            v4 <= 1'b0;
            v5 <= 1'b0;
            v6 <= 1'b0;
            v7 <= 1'b0;
            out_valid <= 1'b0;
        end
    end

    function [19:0] square(input signed [10:0] g);
        reg signed [21:0] p;
        begin
            p = g * g;
            square = p[19:0];
        end
    endfunction

    function signed [20:0] cross_product(input signed [10:0] a, input signed [10:0] b);
        reg signed [21:0] p;
        begin
            p = a * b;
            // |a b| <= 1020^2 < 2^20: the low 21 bits hold the signed value.
            cross_product = p[20:0];
        end
    endfunction
endmodule
`default_nettype wire
