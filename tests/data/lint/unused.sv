// A register set on every clock and read by nothing.
module unused (
  input  logic clk,
  input  logic a,
  output logic y
);
  logic q, spare_q;
  always_ff @(posedge clk) begin
    q <= a;
    spare_q <= !a;
  end
  assign y = q;
endmodule
