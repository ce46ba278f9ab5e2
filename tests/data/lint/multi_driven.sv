// A register written by two always_ff processes: two drivers, whichever runs last wins.
module multi_driven (
  input  logic clk,
  input  logic a,
  input  logic b,
  output logic y
);
  logic q;
  always_ff @(posedge clk) q <= a;
  always_ff @(posedge clk) q <= b;
  assign y = q;
endmodule
