// The control: one driver for each signal, every signal read; a signal unused by design is
// marked so where it is declared.
module clean (
  input  logic clk,
  input  logic a,
  input  logic b,
  output logic y
);
  logic q;
  (* maybe_unused *) logic spare;
  always_ff @(posedge clk) q <= a;
  assign spare = b;
  assign y = q;
endmodule
