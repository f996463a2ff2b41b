#!/usr/bin/env python3
"""Renders a small synthetic multi-view scene for the demo and the end-to-end test.

The scene is an open room (floor, back wall, two side walls) with a few boxes
standing on the floor, so every view sees several non-coplanar surfaces and
the mapper has real 3-D structure to work with (a single plane would make the
essential matrix degenerate). Every surface carries its own procedural texture
(multi-octave value noise, random blobs, lines and polygons) defined in
surface coordinates, so the same physical point looks the same from every
view and SIFT finds thousands of repeatable features.

Rendering is plain ray casting: one ray per sub-pixel, intersected with every
textured rectangle, nearest hit wins; 2x2 super-sampling removes aliasing.
Only numpy and Pillow are needed.

Outputs in OUT_DIR:
  images/view_XX.jpg      the rendered views
  intrinsics.txt          "PINHOLE W H fx fy cx cy" (COLMAP's camera_params order)
  gt/cameras.txt, gt/images.txt, gt/points3D.txt
                          ground truth in COLMAP's text model format
                          (world-to-camera rotation quaternion and translation)
"""

import argparse
import os
import sys
import time

import numpy as np
from PIL import Image, ImageDraw, ImageFilter

TEXELS_PER_METRE = 320


# --------------------------------------------------------------------------
# Procedural textures
# --------------------------------------------------------------------------

def value_noise(rng, width, height, cell):
    """Smooth random field: a coarse random grid upsampled bicubically."""
    gw = max(2, width // cell + 2)
    gh = max(2, height // cell + 2)
    grid = rng.random((gh, gw), dtype=np.float32)
    img = Image.fromarray((grid * 255).astype(np.uint8), mode="L")
    img = img.resize((gw * cell, gh * cell), Image.BICUBIC)
    return np.asarray(img, dtype=np.float32)[:height, :width] / 255.0


def make_texture(rng, width, height):
    """An RGB texture rich in corners and blobs at several scales."""
    rgb = np.zeros((height, width, 3), dtype=np.float32)
    # Noise octaves: coarse shading down to fine grain, each with its own tint.
    for cell, weight in ((96, 0.35), (32, 0.3), (12, 0.25), (5, 0.15)):
        tint = rng.uniform(0.4, 1.0, size=3).astype(np.float32)
        rgb += weight * value_noise(rng, width, height, cell)[..., None] * tint
    base = Image.fromarray(np.clip(rgb * 255, 0, 255).astype(np.uint8), "RGB")

    draw = ImageDraw.Draw(base)
    area = width * height
    # Random blobs (ellipses) of many sizes: blob detectors love them.
    for _ in range(area // 1500):
        r = int(rng.integers(3, 40) * (rng.random() ** 2) + 3)
        x, y = rng.integers(0, width), rng.integers(0, height)
        ry = int(r * rng.uniform(0.5, 1.5))
        color = tuple(int(c) for c in rng.integers(0, 256, size=3))
        draw.ellipse([x - r, y - ry, x + r, y + ry], fill=color)
    # Random polygons give sharp corners.
    for _ in range(area // 6000):
        cx, cy = rng.integers(0, width), rng.integers(0, height)
        n = int(rng.integers(3, 7))
        size = rng.uniform(6, 45)
        pts = [(float(cx + size * rng.uniform(-1, 1)), float(cy + size * rng.uniform(-1, 1)))
               for _ in range(n)]
        color = tuple(int(c) for c in rng.integers(0, 256, size=3))
        draw.polygon(pts, fill=color)
    # Random line segments.
    for _ in range(area // 8000):
        x0, y0 = rng.integers(0, width), rng.integers(0, height)
        length = rng.uniform(10, 120)
        angle = rng.uniform(0, np.pi)
        x1, y1 = x0 + length * np.cos(angle), y0 + length * np.sin(angle)
        color = tuple(int(c) for c in rng.integers(0, 256, size=3))
        draw.line([(float(x0), float(y0)), (float(x1), float(y1))], fill=color,
                  width=int(rng.integers(1, 5)))
    # Slight blur so that texels do not alias into pixel-level noise.
    base = base.filter(ImageFilter.GaussianBlur(0.7))
    return np.asarray(base, dtype=np.float32) / 255.0


# --------------------------------------------------------------------------
# Scene geometry: textured rectangles origin + u * edge_u + v * edge_v
# --------------------------------------------------------------------------

class Rect:
    def __init__(self, origin, edge_u, edge_v, texture, shade):
        self.origin = np.asarray(origin, dtype=np.float64)
        self.edge_u = np.asarray(edge_u, dtype=np.float64)
        self.edge_v = np.asarray(edge_v, dtype=np.float64)
        self.texture = texture
        # Constant Lambertian factor: surfaces of different orientation get
        # different brightness, as under a distant light.
        self.shade = shade


def box_faces(rng, center, size, light):
    """The five visible faces (no bottom) of an axis-aligned box on the floor."""
    cx, cy = center
    sx, sy, sz = size
    x0, x1 = cx - sx / 2, cx + sx / 2
    y0, y1 = cy - sy / 2, cy + sy / 2
    corners_and_edges = [
        ((x0, y0, 0), (sx, 0, 0), (0, 0, sz)),   # front  (-y)
        ((x1, y1, 0), (-sx, 0, 0), (0, 0, sz)),  # back   (+y)
        ((x0, y1, 0), (0, -sy, 0), (0, 0, sz)),  # left   (-x)
        ((x1, y0, 0), (0, sy, 0), (0, 0, sz)),   # right  (+x)
        ((x0, y0, sz), (sx, 0, 0), (0, sy, 0)),  # top    (+z)
    ]
    faces = []
    for origin, eu, ev in corners_and_edges:
        faces.append(textured_rect(rng, origin, eu, ev, light))
    return faces


def textured_rect(rng, origin, edge_u, edge_v, light):
    eu, ev = np.asarray(edge_u, float), np.asarray(edge_v, float)
    tw = max(16, int(np.linalg.norm(eu) * TEXELS_PER_METRE))
    th = max(16, int(np.linalg.norm(ev) * TEXELS_PER_METRE))
    normal = np.cross(eu, ev)
    normal /= np.linalg.norm(normal)
    shade = 0.55 + 0.45 * abs(float(normal @ light))
    return Rect(origin, eu, ev, make_texture(rng, tw, th), shade)


def build_scene(seed):
    rng = np.random.default_rng(seed)
    light = np.array([0.3, -0.5, 0.8])
    light /= np.linalg.norm(light)
    rects = [
        textured_rect(rng, (-3, -2, 0), (6, 0, 0), (0, 5, 0), light),   # floor
        textured_rect(rng, (-3, 3, 0), (6, 0, 0), (0, 0, 3), light),    # back wall
        textured_rect(rng, (-3, -2, 0), (0, 5, 0), (0, 0, 3), light),   # left wall
        textured_rect(rng, (3, 3, 0), (0, -5, 0), (0, 0, 3), light),    # right wall
    ]
    rects += box_faces(rng, (-1.0, 0.6), (1.0, 0.9, 1.1), light)
    rects += box_faces(rng, (0.9, 1.4), (0.8, 0.8, 1.6), light)
    rects += box_faces(rng, (0.3, -0.6), (0.6, 0.7, 0.5), light)
    return rects


# --------------------------------------------------------------------------
# Cameras
# --------------------------------------------------------------------------

def look_at(center, target, up=(0.0, 0.0, 1.0)):
    """World-to-camera rotation, COLMAP axes: x right, y down, z forward."""
    forward = np.asarray(target, float) - center
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


def camera_poses(num_views):
    """Cameras on an arc in front of the room, looking at its middle."""
    target = np.array([0.0, 0.8, 0.8])
    poses = []
    for i in range(num_views):
        angle = np.deg2rad(-35 + 70 * i / max(1, num_views - 1))
        radius = 5.2 + 0.3 * np.sin(3 * angle)
        height = 1.7 + 0.4 * np.cos(2.5 * i)
        center = np.array([radius * np.sin(angle), 0.8 - radius * np.cos(angle), height])
        R = look_at(center, target + np.array([0.15 * np.sin(i), 0.0, 0.1 * np.cos(i)]))
        poses.append((R, center))
    return poses


def rotation_to_quaternion(R):
    """[w, x, y, z] with w >= 0."""
    m = R
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


# --------------------------------------------------------------------------
# Ray casting
# --------------------------------------------------------------------------

def sample_bilinear(texture, u, v):
    h, w, _ = texture.shape
    x = np.clip(u * (w - 1), 0, w - 1.001)
    y = np.clip((1.0 - v) * (h - 1), 0, h - 1.001)
    x0 = x.astype(np.int32)
    y0 = y.astype(np.int32)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    top = texture[y0, x0] * (1 - fx) + texture[y0, x0 + 1] * fx
    bottom = texture[y0 + 1, x0] * (1 - fx) + texture[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def projected_window(rect, R, center, focal, width, height, ss):
    """Sub-pixel window (y0, y1, x0, x1) that can contain the rectangle, so
    that each rectangle is only intersected with the rays that may hit it."""
    corners = [rect.origin, rect.origin + rect.edge_u, rect.origin + rect.edge_v,
               rect.origin + rect.edge_u + rect.edge_v]
    cam = np.array([R @ (c - center) for c in corners])
    H, W = height * ss, width * ss
    if (cam[:, 2] <= 1e-3).any():
        return 0, H, 0, W  # crosses the image plane: no safe bound, test every ray
    x = (focal * cam[:, 0] / cam[:, 2] + width / 2) * ss
    y = (focal * cam[:, 1] / cam[:, 2] + height / 2) * ss
    x0, x1 = int(np.clip(np.floor(x.min()) - 1, 0, W)), int(np.clip(np.ceil(x.max()) + 1, 0, W))
    y0, y1 = int(np.clip(np.floor(y.min()) - 1, 0, H)), int(np.clip(np.ceil(y.max()) + 1, 0, H))
    return y0, y1, x0, x1


def render_view(rects, R, center, width, height, focal, supersample):
    ss = supersample
    W, H = width * ss, height * ss
    # Sub-pixel centres in full-resolution pixel units; the centre of the
    # upper-left pixel is (0.5, 0.5) as in COLMAP. Rays are kept in world
    # coordinates (camera-to-world rotation is R^T).
    xs = ((np.arange(W, dtype=np.float32) + 0.5) / ss - width / 2) / focal
    ys = ((np.arange(H, dtype=np.float32) + 0.5) / ss - height / 2) / focal
    Rt = R.T.astype(np.float32)
    dirs = (xs[None, :, None] * Rt[:, 0] + ys[:, None, None] * Rt[:, 1] + Rt[:, 2])

    best_t = np.full((H, W), np.inf, dtype=np.float32)
    best_id = np.full((H, W), -1, dtype=np.int16)
    best_u = np.zeros((H, W), dtype=np.float32)
    best_v = np.zeros((H, W), dtype=np.float32)
    for k, rect in enumerate(rects):
        y0, y1, x0, x1 = projected_window(rect, R, center, focal, width, height, ss)
        if y0 >= y1 or x0 >= x1:
            continue
        d = dirs[y0:y1, x0:x1]
        normal = np.cross(rect.edge_u, rect.edge_v).astype(np.float32)
        rel = (center - rect.origin).astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -(rel @ normal) / (d @ normal)
        # Rectangle edges are orthogonal, so its coordinates are projections.
        eu = (rect.edge_u / (rect.edge_u @ rect.edge_u)).astype(np.float32)
        ev = (rect.edge_v / (rect.edge_v @ rect.edge_v)).astype(np.float32)
        u = rel @ eu + t * (d @ eu)
        v = rel @ ev + t * (d @ ev)
        win_t = best_t[y0:y1, x0:x1]
        hit = (t > 1e-6) & (t < win_t) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
        win_t[hit] = t[hit]
        best_id[y0:y1, x0:x1][hit] = k
        best_u[y0:y1, x0:x1][hit] = u[hit]
        best_v[y0:y1, x0:x1][hit] = v[hit]

    best_id, best_u, best_v = best_id.ravel(), best_u.ravel(), best_v.ravel()
    color = np.full((H * W, 3), 0.08, dtype=np.float32)  # dark background
    for k, rect in enumerate(rects):
        idx = np.nonzero(best_id == k)[0]
        if idx.size:
            color[idx] = sample_bilinear(rect.texture, best_u[idx], best_v[idx]) * rect.shade
    image = color.reshape(height, ss, width, ss, 3).mean(axis=(1, 3))
    return np.clip(image * 255 + 0.5, 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------

def write_ground_truth(out_dir, names, poses, width, height, focal):
    gt_dir = os.path.join(out_dir, "gt")
    os.makedirs(gt_dir, exist_ok=True)
    cx, cy = width / 2, height / 2
    with open(os.path.join(out_dir, "intrinsics.txt"), "w") as f:
        f.write(f"PINHOLE {width} {height} {focal:.6f} {focal:.6f} {cx:.6f} {cy:.6f}\n")
    with open(os.path.join(gt_dir, "cameras.txt"), "w") as f:
        f.write("# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[fx fy cx cy]\n")
        f.write(f"1 PINHOLE {width} {height} {focal:.6f} {focal:.6f} {cx:.6f} {cy:.6f}\n")
    with open(os.path.join(gt_dir, "images.txt"), "w") as f:
        f.write("# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (world-to-camera)\n")
        f.write("# (empty line: no 2-D points)\n")
        for i, (name, (R, center)) in enumerate(zip(names, poses)):
            q = rotation_to_quaternion(R)
            t = -R @ center
            f.write(f"{i + 1} {q[0]:.12f} {q[1]:.12f} {q[2]:.12f} {q[3]:.12f} "
                    f"{t[0]:.12f} {t[1]:.12f} {t[2]:.12f} 1 {name}\n\n")
    with open(os.path.join(gt_dir, "points3D.txt"), "w") as f:
        f.write("# no points: the ground truth holds cameras only\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--num_views", type=int, default=10)
    parser.add_argument("--width", type=int, default=800)
    parser.add_argument("--height", type=int, default=600)
    parser.add_argument("--focal", type=float, default=700.0)
    parser.add_argument("--supersample", type=int, default=2)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()

    start = time.time()
    image_dir = os.path.join(args.out_dir, "images")
    os.makedirs(image_dir, exist_ok=True)
    rects = build_scene(args.seed)
    poses = camera_poses(args.num_views)
    names = []
    for i, (R, center) in enumerate(poses):
        name = f"view_{i:02d}.jpg"
        pixels = render_view(rects, R, center, args.width, args.height, args.focal,
                             args.supersample)
        Image.fromarray(pixels, "RGB").save(os.path.join(image_dir, name), quality=95)
        names.append(name)
    write_ground_truth(args.out_dir, names, poses, args.width, args.height, args.focal)
    print(f"Rendered {len(names)} views of {args.width}x{args.height} into {image_dir} "
          f"in {time.time() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
