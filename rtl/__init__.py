"""RTL generator: config -> derived constants -> Jinja2 templates -> SystemVerilog."""
