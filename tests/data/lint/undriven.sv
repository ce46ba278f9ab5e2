// A signal read and never driven.
module undriven (
  input  logic a,
  output logic y
);
  logic enable;
  assign y = a & enable;
endmodule
