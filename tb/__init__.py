"""cocotb testbenches and scoreboards."""
