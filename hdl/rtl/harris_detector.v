// The board's Harris detector for one camera (board-icd.md section 2), one pixel per clock,
// with line buffers only: harris_sobel -> harris_window -> harris_response -> harris_nms, then
// the MAX_FEATURES limit.
//
// Use: pulse `start` with the registers (latched); then give exactly WIDTH x HEIGHT pixels in
// raster order, one per clock at most (`pixel_valid`; gaps allowed anywhere). Features leave
// in raster order on `feature_valid` with their index 0, 1, ..., at most MAX_FEATURES of them;
// `overflow` rises when one more was found. `done` pulses once every feature is out, a fixed
// PIPELINE_LATENCY clocks after the last pixel; `start` again only after it (the registers and
// the coordinates in flight are the frame's). With registers outside the ICD's ranges
// (`config_error` says which) the frame is ignored: no feature, `done` right after `start`.
//
// Tokens carry the coordinates (x, y) of the input pixel that produced them; each stage's
// value refers to a fixed offset from them (see each module), so the feature decided with the
// token of pixel (x, y) is at (x - 4, y - 4). A stage's window or line buffer may hold values of
// the previous row or image at the image's edges; those are only ever combined into values the
// ICD does not define, which harris_nms never compares (it tests 4 <= x - 4 and 4 <= y - 4 only,
// and the neighbourhood of such a pixel is defined). So no stage needs a reset between images.
`default_nettype none
module harris_detector #(
    // Line buffer depth: the widest image this instance takes (the ICD allows up to 4095).
    parameter integer MAX_WIDTH = 4095
) (
    input  wire               clk,
    input  wire               rst,
    input  wire               start,
    input  wire [11:0]        width,
    input  wire [11:0]        height,
    input  wire signed [31:0] threshold,
    input  wire [9:0]         max_features,
    input  wire               pixel_valid,
    input  wire [7:0]         pixel,
    output reg                feature_valid,
    output reg  [9:0]         feature_index,
    output reg  [15:0]        feature_x_q4,
    output reg  [15:0]        feature_y_q4,
    output reg  signed [31:0] feature_r,
    output reg                done,
    output reg                busy,
    output reg  [9:0]         feature_count,
    output reg                overflow,
    // Bit 0: WIDTH outside 16..=4095 or above MAX_WIDTH; bit 1: HEIGHT outside 16..=4095;
    // bit 2: MAX_FEATURES outside 1..=1023.
    output reg  [2:0]         config_error
);
`include "harris_consts.vh"

    // The frame's registers, latched at `start`.
    reg [11:0]        last_x, last_y;                   // WIDTH - 1, HEIGHT - 1
    reg signed [31:0] frame_threshold;
    reg [9:0]         frame_max;
    // The input position and whether pixels are still expected.
    reg               taking;
    reg [11:0]        in_x, in_y;

    wire token_valid = taking && pixel_valid;
    wire token_last = (in_x == last_x) && (in_y == last_y);

    // The pipeline.
    wire               g_valid;
    wire [11:0]        g_x, g_y;
    wire signed [10:0] gx, gy;
    harris_sobel #(.MAX_WIDTH(MAX_WIDTH)) sobel (
        .clk(clk), .rst(rst),
        .in_valid(token_valid), .in_x(in_x), .in_y(in_y), .in_pixel(pixel),
        .out_valid(g_valid), .out_x(g_x), .out_y(g_y), .out_gx(gx), .out_gy(gy)
    );

    wire               s_valid;
    wire [11:0]        s_x, s_y;
    wire [24:0]        sxx, syy;
    wire signed [25:0] sxy;
    harris_window #(.MAX_WIDTH(MAX_WIDTH)) window (
        .clk(clk), .rst(rst),
        .in_valid(g_valid), .in_x(g_x), .in_y(g_y), .in_gx(gx), .in_gy(gy),
        .out_valid(s_valid), .out_x(s_x), .out_y(s_y),
        .out_sxx(sxx), .out_syy(syy), .out_sxy(sxy)
    );

    wire               r_valid;
    wire [23:0]        r_tag;
    wire signed [31:0] r;
    harris_response #(.TAG_BITS(2 * COORD_BITS)) response (
        .clk(clk), .rst(rst),
        .in_valid(s_valid), .in_tag({s_y, s_x}), .in_sxx(sxx), .in_syy(syy), .in_sxy(sxy),
        .out_valid(r_valid), .out_tag(r_tag), .out_r(r)
    );

    wire               nms_valid, nms_feature;
    wire [11:0]        nms_x, nms_y;
    wire [15:0]        nms_x_q4, nms_y_q4;
    wire signed [31:0] nms_r;
    harris_nms #(.MAX_WIDTH(MAX_WIDTH)) nms (
        .clk(clk), .rst(rst), .threshold(frame_threshold),
        .in_valid(r_valid), .in_x(r_tag[11:0]), .in_y(r_tag[23:12]), .in_r(r),
        .out_valid(nms_valid), .out_x(nms_x), .out_y(nms_y), .out_feature(nms_feature),
        .out_x_q4(nms_x_q4), .out_y_q4(nms_y_q4), .out_r(nms_r)
    );

    wire [2:0] start_error = {
        max_features == 0,
        height < MIN_SIZE,
        (width < MIN_SIZE) || (width > MAX_WIDTH)
    };

    always @(posedge clk) begin
        if (rst) begin
            taking <= 1'b0;
            busy <= 1'b0;
            done <= 1'b0;
            feature_count <= 0;
            overflow <= 1'b0;
            config_error <= 0;
        end else if (start) begin
            last_x <= width - 1'b1;
            last_y <= height - 1'b1;
            frame_threshold <= threshold;
            frame_max <= max_features;
            in_x <= 0;
            in_y <= 0;
            config_error <= start_error;
            taking <= start_error == 0;
            busy <= start_error == 0;
            done <= start_error != 0;
            feature_count <= 0;
            overflow <= 1'b0;
        end else begin
            done <= 1'b0;
            if (token_valid) begin
                if (token_last) begin
                    taking <= 1'b0;
                end
                if (in_x == last_x) begin
                    in_x <= 0;
                    in_y <= in_y + 1'b1;
                end else begin
                    in_x <= in_x + 1'b1;
                end
            end
            // The MAX_FEATURES limit (ICD step 7): the first ones in raster order are sent.
            if (nms_valid && nms_feature) begin
                if (feature_count == frame_max) begin
                    overflow <= 1'b1;
                end else begin
                    feature_count <= feature_count + 1'b1;
                end
            end
            if (nms_valid && nms_x == last_x && nms_y == last_y && busy) begin
                busy <= 1'b0;
                done <= 1'b1;
            end
        end
    end

    always @(posedge clk) begin
        feature_valid <= !rst && !start && nms_valid && nms_feature && feature_count != frame_max;
        feature_index <= feature_count;
        feature_x_q4 <= nms_x_q4;
        feature_y_q4 <= nms_y_q4;
        feature_r <= nms_r;
    end

endmodule
`default_nettype wire
