#!/usr/bin/env python3
"""Renders the model cards models/fish_det.md and models/fish_depth.md from training/metrics.json."""
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
MODELS = os.path.join(HERE, "..", "models")


def ms(r):
    return f"{r[0]:.2f} (p90 {r[1]:.2f})"


def autocast_note(d):
    """Ends a sentence about training: how the network ran (fp32 unless recorded otherwise)."""
    return ", under bf16 autocast with channels-last tensors (oneDNN, native bf16)" if d.get("autocast") == "bf16" else ""


def budget_note(d):
    run = d.get("epochs_run", d["epochs"])
    return f" (the time budget stopped it in epoch {run})" if run < d["epochs"] else ""


def timing_note(d):
    """The sentence under each card's table: how and on which CPU the timings were taken."""
    return ("Timings: ONNX Runtime 1.31.1 (Python), batch 1,\n"
            f"{d.get('timing', 'median of 50 runs after 5 warm-ups')},\n"
            f"on a 2-vCPU {d.get('timed_on', 'Xeon (AVX-512 VNNI)')} shared with other jobs;\n"
            "`make bench-infer` measures the same in fme.")


def recipe_cmd(d):
    """The command that trained a model: the training/Makefile target recorded by train.py (`--recipe`)."""
    if d.get("recipe") == "bundled":
        return "`make -C training bundled` (train.sh on whole frames, longer time budgets; training/Makefile)"
    return "`bash training/train.sh` (or `make -C training all`)"


def sub_note(st):
    """The card's sentence for a head with sub-cells (output stride below 4)."""
    if st == 4:
        return ""
    n = 4 // st
    return (f"\nThe head's last 1x1 convolution predicts {n}x{n} sub-cells per stride-4 cell, so heat map and\n"
            f"boxes come out at stride {st}: two fish one stride-4 cell apart keep two peaks.")


def quant_note(d):
    """Which parts of the int8 detector stay in float."""
    first = ""
    if d.get("float_stem"):
        first = "the first convolution (it reads the 3-channel image; faster in float here) and\n"
    return (f"\nIn the int8 file {first}the head's last 1x1 convolution (a Gemm on channels-last activations)\n"
            "and the in-graph decode stay in float." + upsample_note(d))


def upsample_note(d):
    """The int8 file's upsamples, when `quant.channels_last_upsample` rewrote those of the kept variant."""
    if not d.get(f"int8_{d.get('int8_kept')}_upsamples_rewritten"):
        return ""
    return ("\nThe int8 file's nearest 2x upsamples are copies of the uint8 tensor in channels-last order\n"
            "(`quant.channels_last_upsample`: the same bytes as the Resize they replace,\n"
            "which ONNX Runtime runs slowly there).")


# What each det.ARCHS layout leaves out of the full one (kept here: cards.py does not import torch).
_ONE_S8_BLOCK = "one residual block at stride 8 instead of two"
_NO_HEAD_CONV = "no 3x3 convolution between the FPN's stride-4 output and the head's 1x1 convolution"
_S8_48 = "48 channels at stride 8 and in the FPN instead of 64"


def _sep(where):
    return f"the stride-1 3x3 convolutions {where} depthwise-separable (3x3 per channel, then 1x1)"


ARCH_PARTS = {"slim": (_ONE_S8_BLOCK, _NO_HEAD_CONV), "no_head_conv": (_NO_HEAD_CONV,), "s8_48": (_S8_48,),
              "lean": (_S8_48, _NO_HEAD_CONV), "sep": (_sep("everywhere"),), "sep48": (_sep("at strides 4 and 8"),),
              "s8_48_sep4": (_S8_48, _sep("at stride 4"))}


def arch_note(d):
    """The card's sentence for a detector layout other than the full one (det.ARCHS)."""
    arch = d.get("arch", "full")
    if arch == "full":
        return ""
    parts = ARCH_PARTS.get(arch)
    return f"\nLayout `--det-arch {arch}`: {'; '.join(parts)}." if parts else f"\nLayout: {arch}."


def crop_note(d, detail):
    """Ends a training sentence: the windows the model trained on (then `detail`), when not whole frames."""
    if not d.get("train_crop"):
        return ""
    w, h = d["train_crop"]
    return f", on random {w}x{h} windows of the frames{detail}"


def depth_crop_detail(d):
    """How long the depth network trained on windows (`train.py --depth-crop-until`)."""
    until = d.get("train_crop_until", 1.0)
    return f" for the first {until:.0%} of the run, then on whole frames" if until < 1.0 else ""


def det_card(m):
    d = m["detector"]
    data = d["data"]
    stopped = budget_note(d)
    w, h = d.get("input", [320, 192])
    st = d.get("output_stride", 4)
    rows = []
    for tag in ("fp32", "int8_u8s8", "int8_s8s8"):
        if tag not in d:
            continue
        q = d[tag]["quality"]
        best = max(q, key=lambda x: 2 * x["precision"] * x["recall"] / max(x["precision"] + x["recall"], 1e-9))
        at25 = next((x for x in q if abs(x["conf"] - 0.25) < 1e-6), best)
        rows.append(f"| {tag} | {d[tag]['size_mb']} | {ms(d[tag]['ms_1_thread'])} | {ms(d[tag]['ms_2_threads'])} | "
                    f"{at25['precision']:.3f} / {at25['recall']:.3f} | {best['conf']}: {best['precision']:.3f} / "
                    f"{best['recall']:.3f} |")
    return f"""# fish_det: one-class fish detector (YOLO output layout)

Files: `fish_det_fp32.onnx` and `fish_det_int8.onnx` (static int8, QDQ, {d.get('int8_kept', '?')} kept:
the faster int8 variant on this machine).{quant_note(d)}

## Convention (same as an Ultralytics YOLOv8/YOLO11 detection export)
- Input `images` float32 `[1, 3, {h}, {w}]`, RGB in 0..1, letterboxed (centred, pad 114/255).
  640x384 frames scale by {w / 640:g} with no padding.
- Output `output0` float32 `[1, 5, {w * h // (st * st)}]`: cx, cy, w, h in input pixels, then the fish score
  (sigmoided; no objectness; no NMS in the graph). One column per stride-{st} cell; only local maxima
  of the score map (3x3) have a non-zero score. fme decodes, runs NMS and un-letterboxes in Rust
  (`fme::infer::Detector`).

## Model
Plain 3x3-conv ReLU backbone (strides 2 to 32, residual blocks), top-down FPN to one stride-4
CenterNet-style head (centre heatmap with focal loss; sub-cell offset and log size with L1 and GIoU
on every cell where a fish's heat-map Gaussian is >= 0.4, as TTFNet), box decode and peak extraction
inside the graph.{sub_note(st)}{arch_note(d)} {d.get('params_m', 1.10)} M parameters. Code: `training/det.py`.

## Data
Rendered with `fme synth --preset swarm` (20 to 60 fish, water types I, II, III, 1C, 3C, 5C, 7C,
layouts A to F, 640x384): training seeds {data.get('train_seeds')} ({data['train_frames']} frames from
{len(data['train_sequences'])} sequences); held-out seeds {data.get('val_seeds')} ({data['val_frames']} frames from
{len(data['val_sequences'])} sequences), never trained on. Augmentation: horizontal flip, brightness/contrast.

## Training
{recipe_cmd(d)}: CPU, torch {m.get('torch', '2.15.0')}, AdamW, one-cycle LR,
batch 16, {d['epochs']} epochs requested{stopped}, fixed seeds. Training time on the 2-core machine that trained it (shared):
{d['train_seconds']:.0f} s{autocast_note(d)}{crop_note(d, ' (a fish the window cuts is neither target nor background)')}.

## Quality on the held-out sequences
Precision / recall at IoU 0.5 against the ground-truth boxes clipped to the frame; boxes with
visibility >= 0.5 must be found, less visible ones are "don't care". NMS IoU 0.7 (fme's default).

| file | MB | ms, 1 thread | ms, 2 threads | P / R at conf 0.25 | best F1: conf: P / R |
|---|---|---|---|---|---|
{chr(10).join(rows)}

{timing_note(d)}

## Licence
Weights and code: MIT OR Apache-2.0 (this project). Trained only on synthetic frames from fme's own
generator; no third-party weights or data.

## Limits
Synthetic data only: on a real tank sequence it fires on fragments of fish (precision 0.07, recall
0.20; docs/accuracy.md "Real footage"), and on the real sources' held-out splits it finds almost
nothing. Fine-tune on labelled real frames (`make -C training finetune DATA=DIR`,
docs/training.md "Train on your own cage"); any Ultralytics-layout model can replace this one via
`[detector] model`. The real-fish recipe (`make -C training real`) trains on real images whose
sources and CC BY 4.0 licences are listed in each `../shared/realfish/train/*/SOURCE.md`; its
output is not bundled yet.
"""


def real_depth_note(r):
    """The fine-tune on real frames (`make -C training depth-real`), when the bundled files come from it."""
    if not r:
        return ""
    a = r["args"]
    held = ", ".join(f"{k} {v}" for k, v in r["data"]["held_out"].items())
    def cons(res):
        return ", ".join(f"{k} {v['rho']:+.3f}" for k, v in res["consistency"].items() if v["rho"] is not None)
    return f"""
### Fine-tuned on real frames
The files above were then fine-tuned (`make -C training depth-real`, `training/train_depth_real.py`; from
the synthetic network, folded BatchNorms frozen) for {r['train_seconds']:.0f} s ({r['steps']} steps) with
{a['batch']} renders (the loss above; half of them given a colour cast, haze, blur and noise) and
{a['real_batch']} real images a step, peak learning rate {a['lr']:g}. On the real images, a ranking loss
from the labelled box sizes (in one image, of two fish whose long sides differ by at least
{a['ratio']}x, the longer one's inverse depth should be larger; weight {a['rank_weight']}):
{r['data']['real_pairs']} pairs from {sum(r['data']['real_train'].values())} training images of the real pool
(`../shared/realfish/train`, training splits; `jp-piers-partial` excluded), held out per source:
{held}. Depth consistency (Spearman of inverse depth against box long side, mean over images) on the
held-out images, before -> after, int8: {cons(r['before']['int8'])} -> {cons(r['int8_u8s8'])}.
docs/accuracy.md scores it on a real tank sequence ("Real footage") and gives what it costs in depth at the
fish on fme's held-out four-group sequences against the synthetic-only network ("Depth at the fish").{one_core_note(r)}
"""


def one_core_note(r):
    if r["args"].get("threads") != 1:
        return ""
    return ("\nThe timings below were taken inside that run, pinned to one core, so 2 threads gain nothing there\n"
            "(`make bench-infer` times the files in fme).")


def depth_licence(r):
    if not r:
        return "MIT OR Apache-2.0 (this project); synthetic training data from fme's own generator only."
    return ("Weights and code: MIT OR Apache-2.0 (this project). Fine-tuned on real images under CC BY 4.0\n"
            "(attribution as the licence asks; each source's `SOURCE.md` in `../shared/realfish/train` has the\n"
            "details): Roboflow \"Aquarium Combined\" (Henry Doorly Zoo and National Aquarium photos);\n"
            "Roboflow Universe `g18l5754/fish4knowledge-dataset` (a fixed coastal camera, 2020);\n"
            "DeepFish (Saleh et al., Scientific Reports 10:14671, 2020), boxes from Roboflow Universe\n"
            "`brrrrrrr/deepfish-fmyzf`; Roboflow Universe `detection-utzod/fish_motions` (lab zebrafish).\n"
            "Only box sizes were used from the labels. No third-party weights.")


def depth_card(m):
    d = m["depth"]
    data = d["data"]
    w, h = d.get("input", [320, 192])
    stopped = budget_note(d)
    real = m.get("depth_real")
    # The bundled files are the real-frames fine-tune when there is one: its own timings and scores.
    files = real if real else d
    rows = []
    for tag in ("fp32", "int8_u8s8", "int8_s8s8"):
        if tag not in files:
            continue
        q = files[tag].get("quality") or files[tag]["renders_metric"]
        rows.append(f"| {tag} | {files[tag]['size_mb']} | {ms(files[tag]['ms_1_thread'])} | "
                    f"{ms(files[tag]['ms_2_threads'])} | {q['rmse_m']:.3f} | {q['delta_1.25']:.3f} | {q['n']} |")
    return f"""# fish_depth: small relative-depth network (MiDaS convention)

Files: `fish_depth_fp32.onnx` and `fish_depth_int8.onnx` (static int8, QDQ, {files.get('int8_kept', '?')} kept).

## Convention (MiDaS v2.1 small / Depth Anything V2)
- Input `image` float32 `[1, 3, {h}, {w}]`: the frame resized to {w}x{h} (no aspect keep), RGB,
  `(x/255 - mean) / std` with ImageNet mean (0.485, 0.456, 0.406) and std (0.229, 0.224, 0.225)
  (fme's `[depth]` defaults).
- Output `depth` float32 `[1, {h // 2}, {w // 2}]`: relative inverse depth (larger = nearer, positive), known
  only up to scale and shift; fme fits them to metres with the reference objects (paper eq. 1-2).

## Model
U-Net-style encoder/decoder with 3x3-conv ReLU blocks (strides 2 to 32), output at half the input
resolution, softplus. In the exported graph the last convolution (to one channel) is a depthwise
convolution plus a channel sum, and softplus is Relu(x) + Log(1 + Exp(-|x|)) (`depth.fast_tail`:
the same map up to float rounding, faster in ONNX Runtime); both stay in float in the int8 file.{upsample_note(files)}
Trained with MiDaS' scale- and shift-invariant loss (median / mean absolute
deviation normalisation, 20% trimmed L1, multi-scale gradient matching) on disparity 1/z from the
generator's depth maps, plus a focus term (untrimmed L1 on the normalised maps over the fish box
cores and the reference cubes, the only pixels fme reads; weight {d.get('focus_weight', 0)}). Code: `training/depth.py`.

## Data and training
Rendered like the detector's (see fish_det.md): training seeds {data.get('train_seeds')} ({data['train_frames']} frames
from {len(data['train_sequences'])} sequences), held-out seeds {data.get('val_seeds')}. {recipe_cmd(d)}
with `SKIP=det` for this model alone; {d['epochs']} epochs requested{stopped};
training time {d['train_seconds']:.0f} s on the shared 2-core CPU that trained it{autocast_note(d)}{crop_note(d, depth_crop_detail(d))}.
{real_depth_note(real)}
## Quality on the held-out sequences (layout of each sequence, A to F)
Per frame, scale and shift are fitted in disparity space to the reference cubes' front-face centres
(least squares), then depth at every fish with visibility >= 0.5 (ground-truth box centre, 3x3
median) is compared with the camera z of its body centre.

| file | MB | ms, 1 thread | ms, 2 threads | RMSE m | delta<1.25 | fish |
|---|---|---|---|---|---|---|
{chr(10).join(rows)}

{timing_note(files)}

## Licence
{depth_licence(real)}
"""


def main():
    main_with(json.load(open(sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "metrics.json"))))


def main_with(m):
    if "detector" in m:
        open(os.path.join(MODELS, "fish_det.md"), "w").write(det_card(m))
    if "depth" in m:
        open(os.path.join(MODELS, "fish_depth.md"), "w").write(depth_card(m))


if __name__ == "__main__":
    main()
