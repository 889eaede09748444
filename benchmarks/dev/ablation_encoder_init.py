"""Does notebook 10's verdict depend on where the encoder's weights came from?

The shipped hand encoder continues weights that began as the shipped MSMR-Net's encoder, which was
trained with the multi-path decoder with attention, one of the three decoders the ablation
compares. This script runs the same ablation (``hmt.apps.demo.ablation.run_ablation``: three
variants, three seeds, the encoder frozen) from another encoder file, e.g. run A of the docs page
"Why the
paper starts from pretrained weights", trained from random weights with no decoder at all, and
prints the same comparisons as notebook 10.

    .venv/bin/python benchmarks/dev/ablation_encoder_init.py --encoder runs/encoders/peA.pt \\
        --out runs/ablation_encoder_A

The data are notebook 08's (``runs/intersh_<budget>``, generated when missing).
"""

from __future__ import annotations

import argparse

import numpy as np

import handmesh_tutorial as hmt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--encoder", required=True, help="pose-encoder file, or 'pretrained'")
    ap.add_argument("--out", required=True, help="folder of the nine runs")
    ap.add_argument("--epochs", type=int, default=None, help="epochs per run (default: 2/5 of "
                    "the demo's, as notebook 10)")
    ap.add_argument("--seeds", default="0,1,2")
    args = ap.parse_args()
    cfg = hmt.apps.demo.DemoConfig.from_budget()
    data = hmt.apps.demo.generate_data(f"runs/intersh_{cfg.budget}", cfg, seed=0, progress=False)
    seeds = tuple(int(s) for s in args.seeds.split(","))
    epochs = args.epochs or max(1, 2 * cfg.epochs // 5)
    abl = hmt.apps.demo.ablation.run_ablation(cfg, data, args.out, seeds=seeds, epochs=epochs,
                                         init_encoder=args.encoder)
    runs, base = abl["runs"], abl["baselines"]
    print(f"encoder {args.encoder}, {epochs} epochs, seeds {seeds}")
    for name in hmt.apps.demo.ablation.VARIANTS:
        v = [runs[name, s]["scores"]["pa_mpjpe"] for s in seeds]
        print(f"  {name:>24}: PA-MPJPE {np.mean(v):.2f} (seeds {', '.join(f'{x:.2f}' for x in v)})")
    print(f"  rest hand {base['rest hand']['pa_mpjpe']:.2f}, mean training hand "
          f"{base['mean training hand']['pa_mpjpe']:.2f}")
    for row in hmt.apps.demo.ablation.compare_variants(runs):
        print(f"  {row['a']} - {row['b']}: {row['difference']:+.2f} ({row['low']:+.2f} to "
              f"{row['high']:+.2f})")


if __name__ == "__main__":
    main()
