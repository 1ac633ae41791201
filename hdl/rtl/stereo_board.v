// The camera board's FPGA logic (board-icd.md): two Harris detectors, one per camera, fed in
// lockstep, their features kept in double-buffered feature RAMs, and the packet encoder that
// sends one packet per stereo frame.
//
// Use: pulse `frame_start` with the frame's mid-exposure timestamp `frame_t_us` (and the
// registers, latched then) when `ready` is high; then give WIDTH x HEIGHT pixel pairs in raster
// order, at most one pair per clock (`pixel_valid`). When both images are done, the frame's
// packet goes out on `out_*` while the next frame is already being detected: the features are
// written into one half of each feature RAM while the encoder reads the other. A frame that
// ends while the previous packet is still being sent is dropped (`frames_dropped` counts them),
// and so is a frame whose registers are out of range (`config_error`); either way the frame
// counter advances, so the host sees the gap (ICD section 3). `load_counter` sets the frame
// counter of the next packet.
`default_nettype none
module stereo_board #(
    parameter integer MAX_WIDTH = 4095
) (
    input  wire               clk,
    input  wire               rst,
    // Registers (ICD section 1).
    input  wire [11:0]        width,
    input  wire [11:0]        height,
    input  wire signed [31:0] threshold,
    input  wire [9:0]         max_features,
    input  wire               load_counter,
    input  wire [31:0]        counter_value,
    // Sensors.
    input  wire               frame_start,
    input  wire [63:0]        frame_t_us,
    input  wire               pixel_valid,
    input  wire [7:0]         left_pixel,
    input  wire [7:0]         right_pixel,
    output wire               ready,
    // The byte stream to the vehicle computer.
    output wire               out_valid,
    output wire [7:0]         out_byte,
    input  wire               out_ready,
    // Status.
    output wire [2:0]         config_error,
    output reg  [31:0]        frames_dropped,
    output wire               sending
);
    localparam integer WORD_BITS = 64;                       // {r, y_q4, x_q4}
    localparam integer BUFFER_DEPTH = 2048;                  // two halves of 1024 features
    localparam integer BUFFER_ADDR_BITS = 11;

    // The frame in progress: which half of the feature RAMs it fills, its timestamp, and which
    // detectors have finished it.
    reg        write_half;
    reg [63:0] t_us;
    reg        l_finished, r_finished, in_frame;
    reg [31:0] frame_counter;
    assign ready = !in_frame;

    wire accept_start = frame_start && !in_frame;

    // The detectors.
    wire        l_valid, r_valid, l_done, r_done, l_busy, r_busy, l_overflow, r_overflow;
    wire [9:0]  l_index, r_index, l_count, r_count;
    wire [15:0] l_x_q4, l_y_q4, r_x_q4, r_y_q4;
    wire [31:0] l_r, r_r;
    wire [2:0]  l_error, r_error;
    harris_detector #(.MAX_WIDTH(MAX_WIDTH)) left (
        .clk(clk), .rst(rst), .start(accept_start),
        .width(width), .height(height), .threshold(threshold), .max_features(max_features),
        .pixel_valid(pixel_valid), .pixel(left_pixel),
        .feature_valid(l_valid), .feature_index(l_index), .feature_x_q4(l_x_q4),
        .feature_y_q4(l_y_q4), .feature_r(l_r), .done(l_done), .busy(l_busy),
        .feature_count(l_count), .overflow(l_overflow), .config_error(l_error)
    );
    harris_detector #(.MAX_WIDTH(MAX_WIDTH)) right (
        .clk(clk), .rst(rst), .start(accept_start),
        .width(width), .height(height), .threshold(threshold), .max_features(max_features),
        .pixel_valid(pixel_valid), .pixel(right_pixel),
        .feature_valid(r_valid), .feature_index(r_index), .feature_x_q4(r_x_q4),
        .feature_y_q4(r_y_q4), .feature_r(r_r), .done(r_done), .busy(r_busy),
        .feature_count(r_count), .overflow(r_overflow), .config_error(r_error)
    );
    // Both detectors latch the same registers, so they always agree on the errors.
    assign config_error = l_error;

    // The feature RAMs: address {half, index}.
    wire [9:0]  read_index;
    wire        read_right;
    reg         read_half;
    wire [63:0] l_word, r_word;
    sdp_ram #(.WIDTH(WORD_BITS), .DEPTH(BUFFER_DEPTH), .ADDR_BITS(BUFFER_ADDR_BITS)) left_features (
        .clk(clk), .we(l_valid), .waddr({write_half, l_index}), .wdata({l_r, l_y_q4, l_x_q4}),
        .raddr({read_half, read_index}), .rdata(l_word)
    );
    sdp_ram #(.WIDTH(WORD_BITS), .DEPTH(BUFFER_DEPTH), .ADDR_BITS(BUFFER_ADDR_BITS)) right_features (
        .clk(clk), .we(r_valid), .waddr({write_half, r_index}), .wdata({r_r, r_y_q4, r_x_q4}),
        .raddr({read_half, read_index}), .rdata(r_word)
    );

    // Both images done: hand the half just written to the encoder, or drop the frame.
    wire both_done = in_frame && (l_finished || l_done) && (r_finished || r_done);
    wire encoder_busy;
    reg  send;
    reg  [1:0] send_flags;
    reg  [9:0] send_left, send_right;
    reg  [31:0] send_counter;
    reg  [63:0] send_t_us;

    always @(posedge clk) begin
        send <= 1'b0;
        if (rst) begin
            in_frame <= 1'b0;
            write_half <= 1'b0;
            read_half <= 1'b0;
            frame_counter <= 0;
            frames_dropped <= 0;
        end else begin
            if (load_counter) begin
                frame_counter <= counter_value;
            end
            if (accept_start) begin
                in_frame <= 1'b1;
                l_finished <= 1'b0;
                r_finished <= 1'b0;
                t_us <= frame_t_us;
            end else if (both_done) begin
                in_frame <= 1'b0;
                frame_counter <= frame_counter + 1'b1;
                if (l_error != 0 || encoder_busy || send) begin
                    frames_dropped <= frames_dropped + 1'b1;
                end else begin
                    send <= 1'b1;
                    send_flags <= {r_overflow, l_overflow};
                    send_left <= l_count;
                    send_right <= r_count;
                    send_counter <= frame_counter;
                    send_t_us <= t_us;
                    read_half <= write_half;
                    write_half <= !write_half;
                end
            end else begin
                if (l_done) l_finished <= 1'b1;
                if (r_done) r_finished <= 1'b1;
            end
        end
    end

    packet_encoder encoder (
        .clk(clk), .rst(rst), .start(send),
        .flags(send_flags), .n_left(send_left), .n_right(send_right),
        .frame_counter(send_counter), .t_us(send_t_us),
        .read_index(read_index), .read_right(read_right),
        .left_word(l_word), .right_word(r_word),
        .busy(encoder_busy), .out_valid(out_valid), .out_byte(out_byte), .out_ready(out_ready)
    );
    assign sending = encoder_busy || send;
endmodule
`default_nettype wire
