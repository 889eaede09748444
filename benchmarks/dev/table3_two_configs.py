"""Table 3 in both configurations on a decoder-neutral encoder: the run behind
``handmesh_tutorial/assets/table3_results.json`` (notebook 10, docs page "The network").

Single path, multi-path and multi-path + attention, in the paper's configuration (xyz output, L1
on the vertices) and in the CPU recipe (skinned output, heads, auxiliary losses), from one frozen
pose encoder that no compared decoder has trained, several seeds each, on the demo's data; then
`hmt.apps.demo.table3.summarise_table3` (paired intervals, power, VR bins, the bottleneck test).
Resumable: finished runs are read back. Dev-only: about 25-40 CPU minutes at the defaults (the
encoder's features are computed once per configuration and shared by every run). Example::

    python benchmarks/dev/table3_two_configs.py --data runs/demo/data \
        --encoder runs/neutral_encoder/hand_encoder_pretrained.pt --out runs/table3 \
        --results handmesh_tutorial/assets/table3_results.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import sys
import time


def main(argv=None) -> dict:
    import handmesh_tutorial as hmt
    from handmesh_tutorial._io import file_identity, write_json
    from handmesh_tutorial.apps.demo import DemoConfig, generate_data
    from handmesh_tutorial.apps.demo.table3 import run_table3, summarise_table3
    from handmesh_tutorial.nn.pose_encoder import (
        encoder_lineage,
        encoder_source_path,
        read_pose_encoder,
    )

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="demo data root (train/ and test/; made if "
                   "missing with the demo's default sizes)")
    p.add_argument("--data-seed", type=int, default=0)
    p.add_argument("--encoder", default="neutral",
                   help="'neutral' (default), 'pretrained' or a pose-encoder file")
    p.add_argument("--out", required=True, help="folder of the runs")
    p.add_argument("--results", default=None, help="summary JSON to write")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--configurations", default="paper,cpu")
    p.add_argument("--train-scenes", type=int, default=None, help="default: the demo's 3000")
    p.add_argument("--test-scenes", type=int, default=None, help="default: the demo's 100")
    p.add_argument("--image-size", type=int, default=None,
                   help="scene and crop side, px (default: the demo's 128)")
    p.add_argument("--fine-tune", action="store_true",
                   help="train the encoder too, at 0.1x the rate (default: frozen)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--workers", type=int, default=2, help="scene generator processes")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    sizes = {k: v for k, v in (("train_samples", args.train_scenes),
                               ("test_samples", args.test_scenes),
                               ("image_size", args.image_size),
                               ("render_size", args.image_size)) if v is not None}
    cfg = DemoConfig(workers=args.workers, **sizes,
                     **({"freeze_encoder": 0, "encoder_lr_scale": 0.1} if args.fine_tune else {}))
    data = generate_data(args.data, cfg, seed=args.data_seed, progress=False)
    seeds = tuple(int(s) for s in args.seeds.split(","))
    results = run_table3(data, args.out, encoder=args.encoder, config=cfg,
                         configurations=tuple(args.configurations.split(",")), seeds=seeds,
                         epochs=args.epochs, train_overrides={"device": args.device})
    summary = summarise_table3(results)
    enc_path = encoder_source_path(args.encoder)
    meta = read_pose_encoder(enc_path)[1]
    lineage = encoder_lineage(meta)
    provenance = {
        "command": "python benchmarks/dev/table3_two_configs.py " + " ".join(
            a for a in (sys.argv[1:] if argv is None else argv) if not a.startswith("/")),
        "encoder": {"name": args.encoder, "file": enc_path.name, "lineage": lineage,
                    "sha256": file_identity(enc_path)["sha256"],
                    "validation": (meta.get("history") or [{}])[-1]},
        "data": {"train_seed": args.data_seed, "test_seed": args.data_seed + 1,
                 "train_scenes": cfg.train_samples, "test_scenes": cfg.test_samples,
                 "render_size": cfg.render_size, "image_size": cfg.image_size,
                 "validation": "10 % of the training scenes"},
        "training": {"epochs": args.epochs, "seeds": list(seeds), "batch_size": cfg.batch_size,
                     "lr": cfg.lr, "device": args.device,
                     "encoder": ("fine-tuned at 0.1x the rate" if args.fine_tune
                                 else "frozen, features computed once")},
        "seconds": round(time.perf_counter() - t0, 1),
        "hardware": f"{platform.processor() or platform.machine()}, "
                    f"{__import__('os').cpu_count()} CPUs",
        "library_version": hmt.__version__, "date": datetime.date.today().isoformat(),
    }
    doc = {"provenance": provenance, "summary": summary}
    if args.results:
        write_json(args.results, doc, sort_keys=False)  # Table 3's row order
    for conf, c in summary["configurations"].items():
        print(f"== {conf}: mean hand {c['mean_hand']:.2f}, rest hand {c['rest_hand']:.2f} mm")
        for name, r in c["variants"].items():
            print(f"   {name:>24}: {r['pa_mpjpe']:.2f} +- {r['half_width']:.2f} mm "
                  f"(seeds {', '.join(f'{v:.2f}' for v in r['pa_mpjpe_per_seed'])}), rough "
                  f"{r['roughness_deg']:.1f} deg")
        for pr in c["pairs"]:
            s = pr["scenes"]
            print(f"   {pr['a']} - {pr['b']}: scenes {s['difference']:+.2f} [{s['low']:+.2f}, "
                  f"{s['high']:+.2f}], seeds {pr['seeds']['difference']:+.2f} "
                  f"[{pr['seeds']['low']:+.2f}, {pr['seeds']['high']:+.2f}]; detectable "
                  f"{pr['detectable_scenes']:.2f} (scenes) / {pr['detectable_seeds']:.2f} (seeds)")
    if "bottleneck" in summary:
        b = summary["bottleneck"]
        print(f"bottleneck: spread paper {b['spread_paper']:.2f}, cpu {b['spread_cpu']:.2f}, "
              f"difference {b['difference']:+.2f} [{b['low']:+.2f}, {b['high']:+.2f}]")
    print(json.dumps({"seconds": provenance["seconds"]}))
    return doc


if __name__ == "__main__":
    main()
