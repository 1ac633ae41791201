// ICD step 1: the 3x3 Sobel gradients, one pixel per clock, with two pixel rows of line buffer.
//
// Input tokens are pixels p(x, y) in raster order with their coordinates. Each input token
// gives one output token with the same coordinates carrying the gradient at (x - 1, y - 1),
// computed from pixel rows y - 2 ..= y and columns x - 2 ..= x. Where that centre is outside
// 1 <= x - 1 <= W - 2, 1 <= y - 1 <= H - 2 the value is meaningless (it mixes the previous row's
// or image's pixels); the later stages never use it (see harris_detector.v). Latency 3 clocks.
`default_nettype none
module harris_sobel #(
    parameter integer MAX_WIDTH = 4095
) (
    input  wire                        clk,
    input  wire                        rst,
    input  wire                        in_valid,
    input  wire [11:0]                 in_x,
    input  wire [11:0]                 in_y,
    input  wire [7:0]                  in_pixel,
    output reg                         out_valid,
    output reg  [11:0]                 out_x,
    output reg  [11:0]                 out_y,
    output reg  signed [10:0]          out_gx,
    output reg  signed [10:0]          out_gy
);
`include "harris_consts.vh"
    localparam integer ADDR_BITS = $clog2(MAX_WIDTH);

    // Stage 1: the pixel waits one clock for the line buffer's read of its column.
    reg        v1;
    reg [11:0] x1, y1;
    reg [7:0]  p1;
    // The line buffer holds rows y - 1 (low byte) and y - 2 (high byte) at each column.
    wire [2*PIXEL_BITS-1:0] above;
    sdp_ram #(.WIDTH(2 * PIXEL_BITS), .DEPTH(MAX_WIDTH), .ADDR_BITS(ADDR_BITS)) rows (
        .clk(clk),
        // Written one clock after the read of the same column, so never read and written at
        // once (the next read is of column x + 1 or of a later row).
        .we(v1), .waddr(x1[ADDR_BITS-1:0]), .wdata({above[PIXEL_BITS-1:0], p1}),
        .raddr(in_x[ADDR_BITS-1:0]), .rdata(above)
    );

    // Stage 2: the 3x3 window, columns x (c0), x - 1 (c1), x - 2 (c2); rows top (y - 2),
    // middle (y - 1), bottom (y). It moves only when a pixel arrives.
    reg [7:0] c0_top, c0_mid, c0_bot, c1_top, c1_mid, c1_bot, c2_top, c2_mid, c2_bot;
    // (The centre pixel c1_mid is in neither gradient; it only moves on to c2_mid.)
    reg        v2;
    reg [11:0] x2, y2;

    always @(posedge clk) begin
        v1 <= in_valid;
        x1 <= in_x;
        y1 <= in_y;
        p1 <= in_pixel;

        v2 <= v1;
        x2 <= x1;
        y2 <= y1;
        if (v1) begin
            {c2_top, c2_mid, c2_bot} <= {c1_top, c1_mid, c1_bot};
            {c1_top, c1_mid, c1_bot} <= {c0_top, c0_mid, c0_bot};
            {c0_top, c0_mid, c0_bot} <= {above[2*PIXEL_BITS-1:PIXEL_BITS], above[PIXEL_BITS-1:0], p1};
        end
        // Only the valid bits are reset: a token's data is never used without its valid bit.
        if (rst) begin
            v1 <= 1'b0;
            v2 <= 1'b0;
        end
    end
    // Stage 3: gx = S(x) - S(x - 2) with S = top + 2 mid + bottom; gy = B - T with
    // B = bottom-left + 2 bottom + bottom-right and T the same on the top row. Each sum is at
    // most 4 * 255 = 1020 (10 bits), each difference 11-bit signed.
    wire [9:0] right_sum  = c0_top + {c0_mid, 1'b0} + c0_bot;
    wire [9:0] left_sum   = c2_top + {c2_mid, 1'b0} + c2_bot;
    wire [9:0] bottom_sum = c2_bot + {c1_bot, 1'b0} + c0_bot;
    wire [9:0] top_sum    = c2_top + {c1_top, 1'b0} + c0_top;

    always @(posedge clk) begin
        out_valid <= v2;
        out_x     <= x2;
        out_y     <= y2;
        out_gx    <= $signed({1'b0, right_sum}) - $signed({1'b0, left_sum});
        out_gy    <= $signed({1'b0, bottom_sum}) - $signed({1'b0, top_sum});
        if (rst) begin
            out_valid <= 1'b0;
        end
    end
endmodule
`default_nettype wire
