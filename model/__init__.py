"""The model layer, installed as ``kfpga.model`` (``kfpga/model`` links to this folder): one name for each
module, so that no file is imported twice under two names."""

if __name__ != "kfpga.model":
    raise ImportError(f"model/ is the package kfpga.model: import kfpga.model, not {__name__}")
