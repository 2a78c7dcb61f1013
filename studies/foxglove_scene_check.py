"""An independent look at what Foxglove's 3D panel gets from ``episode.mcap``, beside MuJoCo's own render of
the same tick (made ``results/visual/scene_check_*.png``).

Foxglove cannot run on this machine, so this script does what its 3D panel does with the file, with its own
code: it reads the MCAP with the ``mcap`` reader, decodes the ``foxglove.FrameTransforms`` and
``foxglove.SceneUpdate`` messages with google.protobuf from the descriptors in the file, composes the
transform tree (world -> trunk -> links) at the tick nearest ``--t``, poses every scene entity's primitives
(cubes, spheres, cylinders, arrows, lines) in the world and draws them with matplotlib. Nothing of
``taslel_bench.record.scene`` is used. Beside it, MuJoCo's offscreen render of the steps.parquet row of the
same tick (``taslel_bench.record.video``), from the same viewpoint.

    MUJOCO_GL=egl python -m studies.foxglove_scene_check <run folder> --t 6.2 --out results/visual
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")

VIEW_HALF_M = 0.7  # [m] half size of the drawn box around the trunk (entities centred outside it are left out)
AZIMUTH_DEG, ELEVATION_DEG = 130.0, -18.0  # MuJoCo camera angles (taslel_bench.record.video.CAMERA)


def rotation(q: dict) -> np.ndarray:
    """3x3 matrix of a foxglove Quaternion dict (missing fields are 0, as protobuf's JSON drops zeros)."""
    x, y, z, w = (float(q.get(k, 0.0)) for k in "xyzw")
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])  # fmt: skip


def vec(v: dict | None) -> np.ndarray:
    v = v or {}
    return np.array([float(v.get(k, 0.0)) for k in "xyz"])


def read_tick(mcap_path: Path, t_s: float) -> tuple[float, dict, dict]:
    """(simulated time, FrameTransforms, the last SceneUpdate of each scene topic up to that time) nearest t."""
    from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory
    from mcap.reader import make_reader

    def decoder(schema):
        pool, files = (
            descriptor_pool.DescriptorPool(),
            list(descriptor_pb2.FileDescriptorSet.FromString(schema.data).file),
        )
        while files:
            for f in list(files):
                try:
                    pool.Add(f)
                    files.remove(f)
                except TypeError:
                    continue
        cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
        return lambda data: json_format.MessageToDict(cls.FromString(data), preserving_proto_field_name=True)

    decoders, tf, scenes, best = {}, {}, {}, None
    with open(mcap_path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(topics=["/tf", "/scene/robot", "/scene/terrain",
                                                                              "/scene/contact"]):  # fmt: skip
            sim_t = message.publish_time * 1e-9  # publish time = simulated time
            if sim_t > t_s + 1e-6:
                break
            body = decoders.setdefault(schema.id, decoder(schema))(message.data)
            if channel.topic == "/tf":
                tf, best = body, sim_t
            else:
                scenes[channel.topic] = body
    return best, tf, scenes


def world_frames(tf: dict) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Frame name -> (position, rotation) in the world, composing the parent -> child transforms."""
    by_child = {t["child_frame_id"]: t for t in tf["transforms"]}
    out = {"world": (np.zeros(3), np.eye(3))}

    def pose(name: str):
        if name not in out:
            t = by_child[name]
            p_parent, r_parent = pose(t["parent_frame_id"])
            out[name] = (p_parent + r_parent @ vec(t["translation"]), r_parent @ rotation(t["rotation"]))
        return out[name]

    for name in by_child:
        pose(name)
    return out


def _box_faces(centre, rot, size):
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * size / 2
    pts = centre + corners @ rot.T
    idx = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return [pts[list(i)] for i in idx]


def _clip_box(centre, size, lo, hi):
    """An axis-aligned box cut to the drawn region (the floor is 18 m long)."""
    a, b = np.maximum(centre - size / 2, lo), np.minimum(centre + size / 2, hi)
    return (a + b) / 2, np.maximum(b - a, 0.0)


def draw_entities(ax, update: dict, frames: dict, lo: np.ndarray, hi: np.ndarray) -> int:
    """Draw every primitive of a SceneUpdate posed in the world; returns the number drawn."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    drawn = 0
    for entity in update.get("entities", []):
        p_f, r_f = frames.get(entity.get("frame_id", "world"), (None, None))
        if p_f is None:
            continue
        centres = [
            p_f + r_f @ vec(pr["pose"]["position"]) for k in ("spheres", "cylinders") for pr in entity.get(k, [])
        ]
        if centres and not any(((c >= lo) & (c <= hi)).all() for c in centres):
            continue  # outside the drawn box (matplotlib does not clip 3D artists)
        for cube in entity.get("cubes", []):
            rgba = _rgba(cube)
            c, r = p_f + r_f @ vec(cube["pose"]["position"]), r_f @ rotation(cube["pose"]["orientation"])
            size = vec(cube["size"])
            if np.allclose(r, np.eye(3)) and (size > 2 * VIEW_HALF_M).any():
                c, size = _clip_box(c, size, lo, hi)
            floor = size[2] < 0.02
            faces = _box_faces(c, r, size)[5:6] if floor else _box_faces(c, r, size)  # the floor: its top face
            ax.add_collection3d(Poly3DCollection(faces, facecolor=rgba, edgecolor=(0, 0, 0, 0.3), lw=0.3))
            drawn += 1
        for kind in ("spheres", "cylinders"):
            for prim in entity.get(kind, []):
                c, r = p_f + r_f @ vec(prim["pose"]["position"]), r_f @ rotation(prim["pose"]["orientation"])
                _surface(ax, kind, c, r, vec(prim["size"]), _rgba(prim))
                drawn += 1
        for arrow in entity.get("arrows", []):
            tail = p_f + r_f @ vec(arrow["pose"]["position"])
            d = (
                r_f
                @ rotation(arrow["pose"]["orientation"])[:, 0]
                * (arrow.get("shaft_length", 0) + arrow.get("head_length", 0))
            )
            ax.quiver(*tail, *d, color=_rgba(arrow)[:3], linewidth=2, arrow_length_ratio=0.2)
            drawn += 1
        for line in entity.get("lines", []):
            pts = np.array([p_f + r_f @ vec(p) for p in line.get("points", [])])
            if len(pts):
                ax.plot(*pts.T, color=_rgba(line)[:3], lw=2)
                drawn += 1
    return drawn


def _rgba(prim: dict) -> tuple[float, float, float, float]:
    c = prim.get("color", {})
    return tuple(float(c.get(k, 0.0)) for k in ("r", "g", "b", "a"))


def _surface(ax, kind: str, centre, rot, size, rgba) -> None:
    u = np.linspace(0, 2 * np.pi, 16)
    if kind == "spheres":
        v = np.linspace(0, np.pi, 9)
        x, y, z = np.outer(np.cos(u), np.sin(v)), np.outer(np.sin(u), np.sin(v)), np.outer(np.ones_like(u), np.cos(v))
        local = np.stack([x * size[0] / 2, y * size[1] / 2, z * size[2] / 2], axis=-1)
    else:
        h = np.linspace(-0.5, 0.5, 2)
        local = np.stack([np.outer(np.cos(u), np.ones(2)) * size[0] / 2, np.outer(np.sin(u), np.ones(2)) * size[1] / 2,
                          np.outer(np.ones_like(u), h) * size[2]], axis=-1)  # fmt: skip
    world = centre + local @ rot.T
    ax.plot_surface(world[..., 0], world[..., 1], world[..., 2], color=rgba[:3], alpha=max(rgba[3], 0.2), linewidth=0,
                    shade=True)  # fmt: skip


def foxglove_view(mcap_path: Path, t_s: float, out: Path) -> tuple[float, int, np.ndarray]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_tick, tf, scenes = read_tick(mcap_path, t_s)
    frames = world_frames(tf)
    trunk = frames["trunk"][0]
    lo, hi = trunk - VIEW_HALF_M, trunk + VIEW_HALF_M
    fig = plt.figure(figsize=(4.8, 3.6), dpi=100)
    ax = fig.add_subplot(projection="3d", computed_zorder=False)  # drawn in order: terrain, robot, forces
    drawn = sum(draw_entities(ax, scenes[topic], frames, lo, hi)
                for topic in ("/scene/terrain", "/scene/robot", "/scene/contact") if topic in scenes)  # fmt: skip
    for axis, colour in zip(np.eye(3), ("red", "green", "blue"), strict=True):  # world axes under the trunk, 0.3 m
        ax.quiver(trunk[0], trunk[1], 0.0, *(0.3 * axis), color=colour, linewidth=1.5, arrow_length_ratio=0.15)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(max(lo[2], -0.05), hi[2])
    ax.set_box_aspect((1, 1, (hi[2] - max(lo[2], -0.05)) / (2 * VIEW_HALF_M)))
    ax.view_init(elev=-ELEVATION_DEG, azim=AZIMUTH_DEG + 180.0)  # the MuJoCo camera's position angles
    ax.set_proj_type("persp", focal_length=0.6)
    ax.set_title(f"from episode.mcap: /tf + /scene/*, t = {t_tick:.3f} s", fontsize=8)
    ax.tick_params(labelsize=5)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return t_tick, drawn, trunk


def mujoco_view(run_dir: Path, t_tick: float, out: Path) -> int:
    """MuJoCo's render of the steps.parquet row of the tick the MCAP message came from."""
    from PIL import Image

    from taslel_bench.record.video import RunFrames, plant_of_run, run_record

    steps, summary, events = run_record(run_dir)
    row = int(np.argmin(np.abs(steps["t_s"].to_numpy() - t_tick)))
    frames = RunFrames(plant_of_run(run_dir), steps, 480, 360, summary, events)
    try:
        Image.fromarray(frames.frame(row)).save(out)
    finally:
        frames.renderer.close()
    return row


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--t", type=float, required=True, help="simulated time [s] of the tick to draw")
    ap.add_argument("--out", type=Path, default=Path("results/visual"))
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    fox, muj = args.out / "scene_check_from_mcap.png", args.out / "scene_check_mujoco.png"
    t_tick, drawn, trunk = foxglove_view(args.run_dir / "episode.mcap", args.t, fox)
    row = mujoco_view(args.run_dir, t_tick, muj)
    side = args.out / "scene_check_side_by_side.png"
    from PIL import Image

    a, b = Image.open(fox).convert("RGB"), Image.open(muj).convert("RGB")
    both = Image.new("RGB", (a.width + b.width, max(a.height, b.height)), "white")
    both.paste(a, (0, 0))
    both.paste(b, (a.width, 0))
    both.save(side)
    print(json.dumps({"t_s": t_tick, "primitives_drawn": drawn, "trunk_w_m": trunk.round(4).tolist(), "row": row,
                      "files": [str(fox), str(muj), str(side)]}))  # fmt: skip


if __name__ == "__main__":
    main()
