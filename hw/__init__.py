"""The hw layer, installed as ``kfpga.hw`` (``kfpga/hw`` links to this folder): one name for each
module, so that no file is imported twice under two names."""

if __name__ != "kfpga.hw":
    raise ImportError(f"hw/ is the package kfpga.hw: import kfpga.hw, not {__name__}")
