"""Strong and weak scaling model of the O(N) time-domain engines for a cluster, from the
per-step costs measured here (issue 28).

Usage::

    python bench/transient_scaling_model.py                      # 10^8 DOFs, default cluster
    python bench/transient_scaling_model.py --dofs 8.4e6 --dt 1.5e-4 --duration 1.5
    python bench/transient_scaling_model.py --measured runs.jsonl  # bench/explicit_bench.py --json
    python bench/transient_scaling_model.py --node-bandwidth 400 --cores-per-node 128

No machine with more than 2 cores was available, so cluster runs are modelled, not measured.
A step of the explicit and imex engines is one sparse product with K (Rayleigh damping folded
in: K (u + beta v)), the dashpots' small product, the diagonal mass and vector updates
(:mod:`railvib_hpc.transient.explicit`, :mod:`railvib_hpc.transient.imex`). It is
memory-bandwidth bound, so the model is

``t_step(P) = n b / (e B_rank) + k (m L + 8 g / W) + t_I + t_s``

with ``n = N / P`` DOFs per rank, ``b`` the bytes moved per DOF and step (measured: the
products' traffic x step time / DOFs, ``bench/explicit_bench.py``), ``B_rank`` a rank's share
of its node's STREAM bandwidth, ``e`` the fraction of the triad the products reach (measured
on one rank here), ``k`` halo exchanges per step (one per product with ghost values: 1),
``m = 26`` neighbours of a subdomain of a 3-D box partition, ``L`` and ``W`` the network's
latency and bandwidth, ``g = 3 * 6 (n / 3)^(2/3)`` ghost DOFs of a cubic subdomain of ``n/3``
nodes, and ``t_I`` the imex engine's implicit solve (``--implicit-solve-ms``: the track and building
rows grow with the track and the building, not with the soil, and their factor is spread
over all ranks; it is kept as a constant, an upper bound beyond 8 ranks where MUMPS's triangular
solves stop scaling, ``bench/band_scaling_model.py``), and ``t_s`` the per-step work that
does not shrink with more ranks (the wheel-rail contact with its rail columns and the
vehicle, on every rank or rank 0: ``--serial-ms``). Both are measured on the tiny thesis case
(:data:`MEASURED_IMPLICIT_SOLVE_MS`, :data:`MEASURED_SERIAL_MS`); they set where strong
scaling ends.

The memory per DOF (``--bytes-per-dof``, measured peak of the setup, 1.7-1.9 kB at 1-4 M
DOFs) gives the fewest nodes that hold the model. The model is checked against this
machine's 1- and 2-rank measurements (``--measured``: the 2-rank step predicted from the
1-rank one with the measured two-core bandwidth; printed side by side).
"""

from __future__ import annotations

import argparse
import json
import math

#: Bytes moved per DOF and step (bench/explicit_bench.py's count: 12 B per stored entry of
#: K, 77-81 per row, plus 112 B of vector traffic): 1,034 B at 24 k DOFs, 1,084 B at 1 M.
MEASURED_BYTES_PER_DOF_STEP = 1.06e3
#: Fraction of the one-core STREAM-like triad the products reach at 0.5-4 M DOFs on one rank
#: (bench/explicit_bench.py, docs/transient.md: 61-68 %).
MEASURED_TRIAD_FRACTION = 0.65
#: Per-step work that does not scale with the soil (profile of the tiny thesis case, imex,
#: 14,400 DOFs, 500 steps, one rank, cProfile): the MUMPS solve of the 4,420 implicit
#: (track and building) rows 3.9 ms, the wheel-rail contact (rail columns, shape functions)
#: 1.5 ms.
MEASURED_IMPLICIT_SOLVE_MS = 3.9
MEASURED_SERIAL_MS = 1.5
#: Peak resident memory of the setup per DOF [B] (1.7-1.9 kB measured; the upper value) plus
#: the output buffers of a site run (probes only: negligible; fields: output.window).
MEASURED_BYTES_PER_DOF = 1.9e3
#: Neighbours of a subdomain of a 3-D structured box partition (faces, edges, corners).
NEIGHBOURS_3D = 26
#: Default cluster node: 2 x 32-core sockets, STREAM triad ~200 GB/s per node (a
#: conservative figure for DDR4/DDR5 dual-socket nodes), 256 GB, HDR100 InfiniBand
#: (12.5 GB/s, ~2 us MPI latency).
DEFAULT_NODE = {"cores": 64, "bandwidth_gbs": 200.0, "memory_gb": 256.0,
                "latency_us": 2.0, "network_gbs": 12.5}


def ghost_dofs(n_rank: float) -> float:
    """Ghost DOFs of a cubic subdomain holding ``n_rank`` DOFs (3 per node)."""
    return 3.0 * 6.0 * (n_rank / 3.0) ** (2.0 / 3.0)


def step_time(n_dofs: float, ranks: int, node: dict, bytes_per_dof: float,
              triad_fraction: float, exchanges: int = 1, implicit_s: float = 0.0,
              serial_s: float = 0.0) -> dict[str, float]:
    """Modelled time of one step [s] on ``ranks`` ranks, split into its parts."""
    per_node = min(ranks, node["cores"])
    b_rank = node["bandwidth_gbs"] * 1e9 / per_node
    n = n_dofs / ranks
    compute = n * bytes_per_dof / (triad_fraction * b_rank)
    if ranks == 1:
        halo = 0.0
    else:
        m = min(NEIGHBOURS_3D, ranks - 1)
        halo = exchanges * (m * node["latency_us"] * 1e-6
                            + 8.0 * ghost_dofs(n) / (node["network_gbs"] * 1e9))
    return {"compute": compute, "halo": halo, "implicit": implicit_s, "serial": serial_s,
            "total": compute + halo + implicit_s + serial_s}


def fewest_nodes(n_dofs: float, node: dict, bytes_per_dof: float) -> int:
    """Fewest nodes whose memory holds the model (90 % of each node usable)."""
    return max(1, math.ceil(n_dofs * bytes_per_dof / (0.9 * node["memory_gb"] * 1e9)))


def _hms(seconds: float) -> str:
    h, rem = divmod(int(round(seconds)), 3600)
    return f"{h:d}:{rem // 60:02d}:{rem % 60:02d}"


def strong_table(args, node: dict, b: float, e: float) -> None:
    steps = math.ceil(args.duration / args.dt)
    n0 = fewest_nodes(args.dofs, node, args.bytes_per_dof)
    print(f"\n## Strong scaling: {args.dofs:.3g} DOFs, dt {args.dt:g} s, {args.duration:g} s "
          f"simulated ({steps:,} steps); fewest nodes by memory: {n0}")
    print("| nodes | ranks | DOFs / rank | memory / node [GB] | compute [ms] | halo [ms] | "
          "implicit + serial [ms] | step [ms] | wall time | efficiency |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    base = None
    nodes = n0
    while nodes <= args.max_nodes:
        ranks = nodes * node["cores"]
        t = step_time(args.dofs, ranks, node, b, e, implicit_s=args.implicit_solve_ms / 1e3,
                      serial_s=args.serial_ms / 1e3)
        base = base or (t["total"] * ranks)
        eff = base / (t["total"] * ranks)
        print(f"| {nodes} | {ranks} | {args.dofs / ranks:,.0f} | "
              f"{args.dofs * args.bytes_per_dof / nodes / 1e9:.1f} | {1e3 * t['compute']:.2f} | "
              f"{1e3 * t['halo']:.3f} | {1e3 * (t['implicit'] + t['serial']):.1f} | "
              f"{1e3 * t['total']:.2f} | "
              f"{_hms(steps * t['total'])} | {eff:.0%} |")
        nodes *= 2


def weak_table(args, node: dict, b: float, e: float) -> None:
    print(f"\n## Weak scaling: {args.weak_dofs_per_rank:,.0f} DOFs per rank")
    print("| nodes | ranks | DOFs | step [ms] | of 1 node |")
    print("|---|---|---|---|---|")
    nodes, t1 = 1, None
    while nodes <= args.max_nodes:
        ranks = nodes * node["cores"]
        t = step_time(args.weak_dofs_per_rank * ranks, ranks, node, b, e,
                      implicit_s=args.implicit_solve_ms / 1e3,
                      serial_s=args.serial_ms / 1e3)["total"]
        t1 = t1 or t
        print(f"| {nodes} | {ranks} | {args.weak_dofs_per_rank * ranks:.3g} | {1e3 * t:.2f} | "
              f"{t1 / t:.0%} |")
        nodes *= 2


def check_against(measured: list[dict], two_core_gbs: float) -> None:
    """This machine's 1- and 2-rank steps against the model fitted on the 1-rank ones."""
    print("\n## The model on this machine (2 cores sharing one memory bus)")
    print("| engine | DOFs | ranks | measured step [s] | modelled [s] | model / measured |")
    print("|---|---|---|---|---|---|")
    ones = {(r.get("engine", "explicit"), r["dofs"]): r for r in measured if r["ranks"] == 1}
    for r in measured:
        one = ones.get((r.get("engine", "explicit"), r["dofs"]))
        if one is None:
            continue
        b = one["traffic_gbs"] * 1e9 * one["step_s"] / one["dofs"]
        triad = one["traffic_gbs"] / one.get("triad_fraction", MEASURED_TRIAD_FRACTION)
        e = one["traffic_gbs"] / triad
        node = {**DEFAULT_NODE, "cores": 2, "bandwidth_gbs": two_core_gbs,
                "latency_us": 0.5, "network_gbs": 10.0}       # shared memory, one node
        if r["ranks"] == 1:
            node["bandwidth_gbs"] = triad
        t = step_time(r["dofs"], r["ranks"], node, b, e)["total"]
        print(f"| {r.get('engine', 'explicit')} | {r['dofs']:,} | {r['ranks']} | "
              f"{r['step_s']:.4f} | {t:.4f} | {t / r['step_s']:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dofs", type=float, default=1e8)
    ap.add_argument("--dt", type=float, default=2e-4,
                    help="time step [s] (soil at 80 Hz resolution: 2-4e-4 s)")
    ap.add_argument("--duration", type=float, default=1.5,
                    help="simulated time [s] (a 30 m/s car over ~40 m of track)")
    ap.add_argument("--max-nodes", type=int, default=64)
    ap.add_argument("--cores-per-node", type=int, default=DEFAULT_NODE["cores"])
    ap.add_argument("--node-bandwidth", type=float, default=DEFAULT_NODE["bandwidth_gbs"],
                    help="STREAM triad of one node [GB/s]")
    ap.add_argument("--node-memory", type=float, default=DEFAULT_NODE["memory_gb"])
    ap.add_argument("--latency-us", type=float, default=DEFAULT_NODE["latency_us"])
    ap.add_argument("--network", type=float, default=DEFAULT_NODE["network_gbs"],
                    help="network bandwidth per node [GB/s]")
    ap.add_argument("--bytes-per-dof", type=float, default=MEASURED_BYTES_PER_DOF,
                    help="peak memory per DOF [B]")
    ap.add_argument("--implicit-solve-ms", type=float, default=MEASURED_IMPLICIT_SOLVE_MS,
                    help="imex: the implicit part's solve per step [ms] (0: explicit)")
    ap.add_argument("--serial-ms", type=float, default=MEASURED_SERIAL_MS,
                    help="per-step work that does not scale: contact, vehicle [ms]")
    ap.add_argument("--weak-dofs-per-rank", type=float, default=0.5e6)
    ap.add_argument("--measured", help="JSON lines of bench/explicit_bench.py --json")
    ap.add_argument("--two-core-gbs", type=float, default=41.0,
                    help="this machine's two-core triad [GB/s] (for --measured)")
    args = ap.parse_args()
    node = {"cores": args.cores_per_node, "bandwidth_gbs": args.node_bandwidth,
            "memory_gb": args.node_memory, "latency_us": args.latency_us,
            "network_gbs": args.network}
    b, e = MEASURED_BYTES_PER_DOF_STEP, MEASURED_TRIAD_FRACTION
    print(f"# inputs: {b:.0f} B moved per DOF and step, {e:.0%} of the triad reached "
          f"(measured on one core here); {args.bytes_per_dof:.0f} B peak memory per DOF; "
          f"node: {node}")
    strong_table(args, node, b, e)
    weak_table(args, node, b, e)
    if args.measured:
        with open(args.measured) as f:
            runs = [json.loads(line) for line in f if line.strip()]
        check_against(runs, args.two_core_gbs)


if __name__ == "__main__":
    main()
