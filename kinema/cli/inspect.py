"""`kinema inspect FILE`: what kinema sees in a motion or rig file (.glb/.gltf, .bvh/.bvh.gz, .fbx, .npz).

Prints the joints as a tree, the semantic roles found by name (kinema.naming), the rig parts
kinema.rig.Rig finds (root, axes, contact joints, end effectors, limb chains; ``--rig overrides.json``
replaces them), the humanoid mapping retargeting uses (kinema.retarget: each slot's joint and how it
was found, what could not be mapped; helper bones kept), the clips with their frames, rate and
duration, and for glTF and FBX files the armature scale applied, the helper bones dropped, the skinned
mesh and any warnings. Bad files give a one-line error and exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import positive_float


def register(sub) -> None:
    """Add the `inspect` sub-command to the top-level parser."""
    p = sub.add_parser("inspect", help="show a motion/rig file's joints, rig parts and clips")
    p.add_argument("file", type=Path, help=".glb, .gltf, .bvh, .bvh.gz, .fbx or .npz")
    p.add_argument(
        "--in-scale",
        type=positive_float,
        default=1.0,
        help="BVH input: multiply lengths by this to get metres (0.01 for centimetres)",
    )
    p.add_argument("--rig", type=Path, metavar="OVERRIDES.json", help="rig overrides (see kinema.rig)")
    p.set_defaults(func=run)


#: deeper joints are listed with their depth instead of one more level of indentation
MAX_DRAWN_DEPTH = 40


def joint_tree(skeleton) -> list[str]:
    """One line per joint, drawn as a tree (depth-first, children in skeleton order). Walked with an
    explicit stack (a 5000-joint chain is fine); below `MAX_DRAWN_DEPTH` levels a line shows its depth
    instead of growing its indentation."""
    lines: list[str] = []
    stack = [(0, "  ", True, True, 0)]
    while stack:
        j, prefix, last, top, depth = stack.pop()
        branch = "" if top else ("└─ " if last else "├─ ")
        shown = f"[depth {depth}] " if depth > MAX_DRAWN_DEPTH else ""
        lines.append(f"{prefix}{branch}{shown}{skeleton.names[j]}")
        kids = skeleton.children[j]
        below = prefix if top or depth >= MAX_DRAWN_DEPTH else prefix + ("   " if last else "│  ")
        stack += [(c, below, k == len(kids) - 1, False, depth + 1) for k, c in reversed(list(enumerate(kids)))]
    return lines


def _rig_lines(skeleton, overrides) -> list[str]:
    from kinema.rig import Rig

    rig = Rig.from_skeleton(skeleton, overrides=overrides)
    names = skeleton.names
    limbs = ", ".join(f"{k} ({names[c[0]]}..{names[c[-1]]}, {len(c)} joints)" for k, c in rig.limbs.items())
    roles = ", ".join(f"{r}={names[j]}" for r, j in sorted(skeleton.roles.items(), key=lambda kv: kv[1]))
    return [
        f"roles found by name: {roles or 'none'}",
        f"rig: root {names[rig.root]}, up {list(rig.up)}, forward {list(rig.forward)}",
        f"contact joints ({rig.num_contacts}): {', '.join(rig.joint_names(rig.contacts)) or 'none'}",
        "end effectors: " + (", ".join(f"{k}={names[j]}" for k, j in rig.end_effectors.items()) or "none"),
        f"limbs: {limbs or 'none'}",
    ]


def _clip_lines(clips: dict) -> list[str]:
    width = max((len(n) for n in clips), default=0)
    out = [f"clips ({len(clips)}):"]
    for name, m in clips.items():
        out.append(
            f"  {name:<{width}}  {m.duration:6.2f} s  {m.num_frames:4d} frames @ {m.fps:g} fps"
            + ("  (animated bone translations)" if m.local_translations is not None else "")
        )
    return out


def run(args: argparse.Namespace) -> int:
    from kinema.input_files import check_input_file
    from kinema.io import load_motion
    from kinema.io.gltf import read_gltf
    from kinema.retarget import load_character
    from kinema.retarget.fbx import read_fbx

    check_input_file(args.file, "rig or motion file")
    name = args.file.name.lower()
    lines = []
    if name.endswith(".glb") or name.endswith(".gltf"):
        asset = read_gltf(args.file)
        skeleton, clips = asset.skeleton, asset.motions
        rate = f"{asset.source_fps:g} fps keys" if asset.source_fps else "no key rate"
        lines.append(
            f"{args.file}: glTF rig {skeleton.name!r}, {skeleton.num_joints} joints, "
            f"armature scale {asset.scale:g} applied (lengths in metres), {rate}"
        )
        if asset.helper_joints:
            lines.append(f"helper joints dropped (no skin weight): {', '.join(asset.helper_joints)}")
        mesh = skeleton.mesh
        lines.append(
            "mesh: none"
            if mesh is None
            else f"mesh: {mesh.num_vertices} vertices, {len(mesh.faces)} triangles, {len(mesh.colors)} colours"
        )
        lines += [f"warning: {w}" for w in asset.warnings]
    elif name.endswith(".fbx"):
        fbx = read_fbx(args.file)
        skeleton = fbx.skeleton
        clips = {} if fbx.motion is None else {"first animation": fbx.motion}
        mesh = skeleton.mesh
        lines.append(f"{args.file}: FBX rig {skeleton.name!r}, {skeleton.num_joints} joints (metres, Y up)")
        skin = "none" if mesh is None else f"{mesh.num_vertices} vertices, {len(mesh.faces)} triangles"
        lines.append(f"mesh: {skin}")
    else:
        motion = load_motion(args.file, scale=args.in_scale)
        skeleton, clips = motion.skeleton, {args.file.name: motion}
        lines.append(f"{args.file}: {skeleton.num_joints} joints")
    lines.append("joints:")
    lines += joint_tree(skeleton)
    lines += _rig_lines(skeleton, args.rig)
    lines += load_character(args.file, overrides=args.rig).humanoid().lines()
    lines += _clip_lines(clips)
    print("\n".join(lines))
    return 0
