#!/usr/bin/python3
"""The light of the pixels an 8-bit copy clipped, as a NeRF renders it.

Usage: clipped_light.py SCENE_DIR EXPOSURE RENDER_DIR...

Over the test views of SCENE_DIR, the pixels that scripts/ldr_copy.py with this
EXPOSURE clipped (insert/bg_XXX.exr x EXPOSURE >= 1 in some channel): the sum
of the luminance of RENDER_DIR/r_XXX.exr (`nerfar render --dataset SCENE_DIR
-o RENDER_DIR`) over the same sum of bg_XXX.exr. 1 is the true light; an
8-bit capture's NeRF cannot see past the clip level. Independent of nerfar.
"""
import glob
import os
import sys

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
import cv2  # noqa: E402
import numpy as np  # noqa: E402


def read_rgb(path):
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SystemExit(f"cannot read {path}")
    return img[..., :3][..., ::-1].astype(np.float64)


def luminance(img):
    return 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]


def main(argv):
    if len(argv) < 4:
        raise SystemExit(__doc__)
    scene, exposure, dirs = argv[1], float(argv[2]), argv[3:]
    for d in dirs:
        rendered = true = 0.0
        pixels = 0
        for bg in sorted(glob.glob(os.path.join(scene, "insert", "bg_*.exr"))):
            index = os.path.basename(bg)[3:-4]
            ref = read_rgb(bg)
            out = read_rgb(os.path.join(d, f"r_{index}.exr"))
            clipped = (ref * exposure >= 1.0).any(axis=2)
            rendered += luminance(out)[clipped].sum()
            true += luminance(ref)[clipped].sum()
            pixels += int(clipped.sum())
        print(f"{d}: {pixels} clipped pixels over the test views, rendered light / true = {rendered / true:.3f}")


if __name__ == "__main__":
    main(sys.argv)
