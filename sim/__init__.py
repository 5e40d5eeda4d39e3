"""The sim layer, installed as ``kfpga.sim`` (``kfpga/sim`` links to this folder): one name for each
module, so that no file is imported twice under two names."""

if __name__ != "kfpga.sim":
    raise ImportError(f"sim/ is the package kfpga.sim: import kfpga.sim, not {__name__}")
