#!/usr/bin/python3
"""An 8-bit copy of an HDR dataset, as a camera with a locked exposure would take it.

Usage:
  ldr_copy.py SRC_DATASET DST_DATASET [--format jpg|png|png16] [--quality Q] [--exposure X]

Every image of SRC's transforms_train.json and transforms_test.json (linear EXR)
is multiplied by one exposure, clipped at 1 (the sensor's top), put through the
sRGB curve and quantised to 8 bits (or 16 for png16), then written as JPEG
(quality Q, default 95) or PNG. The exposure (default: 1 over the 99th
percentile of luminance over all training pixels, so that about 1 % of the
pixels clip, as an auto-exposed camera meters) is printed. DST gets the
transforms files pointing at the new images and a camera.json whose response
(Debevec's g(z) = ln(linear(z) / exposure), calib/hdr.h) undoes the sRGB curve
and the exposure, so linearised frames are in SRC's radiance units. Independent
of nerfar (OpenCV and numpy only), so that nerfar's reader is tested by it.
"""
import json
import os
import sys

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
import cv2  # noqa: E402
import numpy as np  # noqa: E402


def srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(v):
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


def read_exr_rgb(path):
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
    if img is None:
        raise SystemExit(f"cannot read {path}")
    return np.maximum(img[..., :3][..., ::-1].astype(np.float64), 0.0)


def luminance(img):
    return 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]


def split_files(src):
    names = [n for n in ("transforms_train.json", "transforms_test.json") if os.path.isfile(os.path.join(src, n))]
    if not names:
        names = ["transforms.json"]
    return names


def main(argv):
    args = [a for a in argv[1:]]
    opts = {"--format": "jpg", "--quality": "95", "--exposure": ""}
    pos = []
    while args:
        a = args.pop(0)
        if a in opts:
            opts[a] = args.pop(0)
        else:
            pos.append(a)
    if len(pos) != 2 or opts["--format"] not in ("jpg", "png", "png16"):
        raise SystemExit(__doc__)
    src, dst = pos
    fmt, quality = opts["--format"], int(opts["--quality"])
    splits = {n: json.load(open(os.path.join(src, n))) for n in split_files(src)}
    train_name = "transforms_train.json" if "transforms_train.json" in splits else "transforms.json"

    if opts["--exposure"]:
        exposure = float(opts["--exposure"])
    else:
        lum = np.concatenate([luminance(read_exr_rgb(os.path.join(src, f["file_path"]))).ravel()
                              for f in splits[train_name]["frames"]])
        exposure = 1.0 / np.percentile(lum, 99)
    print(f"exposure {exposure:.6g} (values above {1 / exposure:.6g} clip)")

    bits = 16 if fmt == "png16" else 8
    top = 2 ** bits - 1
    ext = ".jpg" if fmt == "jpg" else ".png"
    clipped = total = 0
    for name, doc in splits.items():
        for frame in doc["frames"]:
            hdr = read_exr_rgb(os.path.join(src, frame["file_path"]))
            x = hdr * exposure
            clipped += int(np.count_nonzero((x >= 1.0).any(axis=2)))
            total += x.shape[0] * x.shape[1]
            q = np.round(srgb_encode(x) * top).astype(np.uint16 if bits == 16 else np.uint8)
            rel = os.path.splitext(frame["file_path"])[0] + ext
            out = os.path.join(dst, rel)
            os.makedirs(os.path.dirname(out), exist_ok=True)
            params = [cv2.IMWRITE_JPEG_QUALITY, quality] if fmt == "jpg" else []
            if not cv2.imwrite(out, q[..., ::-1], params):
                raise SystemExit(f"cannot write {out}")
            frame["file_path"] = rel
        with open(os.path.join(dst, name), "w") as f:
            json.dump(doc, f, indent=1)
    print(f"{100.0 * clipped / total:.2f}% of the pixels clipped in some channel")

    # g(z) = ln(linear(z) / exposure); level 0 stands for [0, 0.5): its middle, 0.25.
    z = np.maximum(np.arange(256, dtype=np.float64), 0.25) / 255.0
    g = np.log(srgb_decode(z) / exposure)
    cam = {k: splits[train_name][k] for k in ("camera_model", "fl_x", "fl_y", "cx", "cy", "w", "h",
                                               "k1", "k2", "p1", "p2") if k in splits[train_name]}
    cam["response"] = {"model": "debevec_log_exposure", "log_exposure": [g.tolist()] * 3}
    cam["note"] = f"sRGB after an exposure of {exposure:.9g}, clipped at 1: made by scripts/ldr_copy.py from {src}"
    with open(os.path.join(dst, "camera.json"), "w") as f:
        json.dump(cam, f, indent=1)


if __name__ == "__main__":
    main(sys.argv)
