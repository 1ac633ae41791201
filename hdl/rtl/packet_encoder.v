// The feature stream's packet (board-icd.md section 3), one byte per clock at most, with a
// valid/ready handshake towards the link (UART, USB FIFO, UDP payload).
//
//   0  sync 5A A5 3C C3     4  version 1     5  flags (bit 0 left, bit 1 right overflow)
//   6  n_left (u16)         8  n_right       10 reserved 0      12 frame counter (u32)
//   16 timestamp (u64, us)  24 features: x_q4 u16, y_q4 u16, r i32, left ones then right ones
//   24 + 8n  CRC-32 (zlib's, reflected 0xEDB88320) of bytes 4 .. 24 + 8n; all little-endian
//
// `start` takes the packet's header fields; the features are read from the two cameras'
// feature buffers (harris_detector's features in index order) at `read_index`, the word
// {r, y_q4, x_q4}, one clock after the address. `busy` until the last CRC byte is taken.
`default_nettype none
module packet_encoder (
    input  wire        clk,
    input  wire        rst,
    input  wire        start,
    input  wire [1:0]  flags,
    input  wire [9:0]  n_left,
    input  wire [9:0]  n_right,
    input  wire [31:0] frame_counter,
    input  wire [63:0] t_us,
    output wire [9:0]  read_index,
    output wire        read_right,
    input  wire [63:0] left_word,
    input  wire [63:0] right_word,
    output reg         busy,
    output reg         out_valid,
    output reg  [7:0]  out_byte,
    input  wire        out_ready
);
    localparam [31:0] SYNC = 32'hC33CA55A;                 // 5A A5 3C C3, little-endian
    localparam [7:0]  VERSION = 8'd1;
    localparam integer HEADER_BYTES = 24;
    localparam integer FEATURE_BYTES = 8;
    localparam integer CRC_BYTES = 4;
    localparam [31:0] CRC_INIT = 32'hFFFFFFFF;
    localparam [31:0] CRC_POLY = 32'hEDB88320;              // reflected 0x04C11DB7

    localparam [2:0] IDLE = 3'd0, HEADER = 3'd1, ADDRESS = 3'd2, LOAD = 3'd3, FEATURE = 3'd4,
                     CRC = 3'd5;
    reg [2:0]   state;
    reg [191:0] header;            // bytes 0..23, byte 0 in bits 7:0
    reg [4:0]   byte_index;        // within the header, a feature or the CRC
    reg [9:0]   index;             // feature within its camera
    reg         right;             // reading the right camera's features
    reg [9:0]   count_left, count_right;
    reg [63:0]  word;              // the feature being sent, byte 0 in bits 7:0
    reg [31:0]  crc;

    assign read_index = index;
    assign read_right = right;

    wire        take = out_valid && out_ready;
    wire [9:0]  count = right ? count_right : count_left;

    // The next feature after the current one (or none: the CRC follows).
    task next_feature;
        begin
            if (index + 1'b1 < count) begin
                index <= index + 1'b1;
                state <= ADDRESS;
            end else if (!right && count_right != 0) begin
                right <= 1'b1;
                index <= 0;
                state <= ADDRESS;
            end else begin
                state <= CRC;
            end
        end
    endtask

    always @(posedge clk) begin
        if (rst) begin
            state <= IDLE;
            busy <= 1'b0;
            out_valid <= 1'b0;
        end else begin
            case (state)
                IDLE: begin
                    if (start) begin
                        header <= {t_us, frame_counter, 16'd0, 6'd0, n_right, 6'd0, n_left,
                                   6'd0, flags, VERSION, SYNC};
                        count_left <= n_left;
                        count_right <= n_right;
                        byte_index <= 0;
                        index <= 0;
                        right <= n_left == 0;
                        crc <= CRC_INIT;
                        busy <= 1'b1;
                        out_valid <= 1'b1;
                        out_byte <= SYNC[7:0];
                        state <= HEADER;
                    end
                end
                HEADER: if (take) begin
                    if (byte_index >= 4) begin
                        crc <= crc32_byte(crc, out_byte);
                    end
                    if (byte_index == HEADER_BYTES - 1) begin
                        out_valid <= 1'b0;
                        if (count_left == 0 && count_right == 0) begin
                            state <= CRC;
                        end else begin
                            state <= ADDRESS;
                        end
                    end else begin
                        byte_index <= byte_index + 1'b1;
                        out_byte <= header[8 * (byte_index + 1) +: 8];
                    end
                end
                ADDRESS: state <= LOAD;       // read_index is on the buffer's address now
                LOAD: begin
                    word <= right ? right_word : left_word;
                    out_byte <= right ? right_word[7:0] : left_word[7:0];
                    out_valid <= 1'b1;
                    byte_index <= 0;
                    state <= FEATURE;
                end
                FEATURE: if (take) begin
                    crc <= crc32_byte(crc, out_byte);
                    if (byte_index == FEATURE_BYTES - 1) begin
                        out_valid <= 1'b0;
                        next_feature;
                    end else begin
                        byte_index <= byte_index + 1'b1;
                        out_byte <= word[8 * (byte_index + 1) +: 8];
                    end
                end
                CRC: begin
                    if (!out_valid) begin
                        // First clock here: the CRC of everything after the sync is final.
                        out_valid <= 1'b1;
                        out_byte <= ~crc[7:0];
                        byte_index <= 0;
                    end else if (take) begin
                        if (byte_index == CRC_BYTES - 1) begin
                            out_valid <= 1'b0;
                            busy <= 1'b0;
                            state <= IDLE;
                        end else begin
                            byte_index <= byte_index + 1'b1;
                            out_byte <= ~crc[8 * (byte_index + 1) +: 8];
                        end
                    end
                end
                default: state <= IDLE;
            endcase
        end
    end

    // One byte of the reflected CRC-32 (zlib's crc32, CRC-32/ISO-HDLC), bit by bit.
    function [31:0] crc32_byte(input [31:0] crc_in, input [7:0] data);
        integer bit_index;
        reg [31:0] c;
        begin
            c = crc_in ^ {24'd0, data};
            for (bit_index = 0; bit_index < 8; bit_index = bit_index + 1) begin
                c = c[0] ? ((c >> 1) ^ CRC_POLY) : (c >> 1);
            end
            crc32_byte = c;
        end
    endfunction
endmodule
`default_nettype wire
