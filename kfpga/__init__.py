"""kfpga: a Kalman filter from a bit-accurate fixed-point model to Quartus-ready Verilog."""

__version__ = "0.1.0"
