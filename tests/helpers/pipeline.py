"""The shape every stage table of a loop pipeline (:class:`~kfpga.hw.core.LoopPipeline`) must have."""


def stage_table_faults(core):
    """What is wrong with ``core``'s stage table (``cuts``: for each stage count L, the steps the
    pipeline registers after), as messages; empty when nothing is. The stage counts run from 1 with
    no gap; L stages cut L - 1 times, in order, each between two steps: a cut before the first step,
    after the last or twice at one place would give a stage with no step, which adds a cycle of
    latency and its registers and shortens no path."""
    steps = len(core.steps)
    faults = []
    if sorted(core.cuts) != list(range(1, len(core.cuts) + 1)):
        faults.append(f"the stage counts are {sorted(core.cuts)}, not 1..{len(core.cuts)}")
    for stages, cuts in core.cuts.items():
        if len(cuts) != stages - 1:
            faults.append(f"{stages} stages cut {len(cuts)} times, not {stages - 1}")
        if list(cuts) != sorted(set(cuts)) or any(not 0 < cut < steps for cut in cuts):
            faults.append(f"{stages} stages cut at {cuts}: each cut must fall between two of the {steps} steps, in order")
    return faults
