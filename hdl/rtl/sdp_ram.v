// Simple dual-port RAM with one write port and one registered read port: the line buffers and
// the feature buffers. Written so that Yosys infers block RAM (ECP5 DP16KD, iCE40 SB_RAM40_4K)
// and Verilator simulates it as an array. A read of the address being written in the same
// clock returns the old word; the modules never do that (see each use).
`default_nettype none
module sdp_ram #(
    parameter integer WIDTH = 8,
    parameter integer DEPTH = 1024,
    parameter integer ADDR_BITS = 10
) (
    input  wire                 clk,
    input  wire                 we,
    input  wire [ADDR_BITS-1:0] waddr,
    input  wire [WIDTH-1:0]     wdata,
    input  wire [ADDR_BITS-1:0] raddr,
    output reg  [WIDTH-1:0]     rdata
);
    reg [WIDTH-1:0] mem [0:DEPTH-1];

    always @(posedge clk) begin
        if (we) begin
            mem[waddr] <= wdata;
        end
        rdata <= mem[raddr];
    end
endmodule
`default_nettype wire
