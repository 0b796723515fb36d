"""Writes hands/<name>/hand.xml and hands/<name>/spec.json for the four built-in hands (in the
registry's order; a hand's title and order are written once in its spec.json and kept here).

Run from the repository root: ``python hands/build_hands.py``. The MJCF files are generated, not
hand-edited, so that all four hands share one set of conventions:

Hand (root body) frame -- identical to the grasp-site frame orientation:
  +z  palm normal / approach direction (from the palm toward the object),
  +y  direction in which the (open) fingers extend (Franka: the finger-closing axis),
  +x  across the knuckles = the handle's long axis in a power grasp.
The root body origin is the wrist (Franka: the flange). ``grasp_site`` is where the handle centre sits
in a power grasp, with the same orientation as the root, so the root pose follows from the site pose by
a fixed translation (see ``opend_mj.sim.hands.grasp_pose_to_root_pose``).

All geometry is primitive (boxes, capsules, spheres, ellipsoids) with dimensions taken from published
numbers for each hand (see each builder's docstring); nothing is copied from other model files.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from opend_mj.transforms import mat_to_quat

HERE = Path(__file__).resolve().parent


def mat2quat(m: np.ndarray) -> list[float]:
    """Rotation matrix -> (w, x, y, z), rounded for the XML."""
    return [round(float(v), 6) for v in mat_to_quat(m)]


def frame_quat(y_dir, z_dir) -> list[float]:
    """Quaternion of a frame whose +y is ``y_dir`` and +z is (the part of) ``z_dir`` orthogonal to it."""
    y = np.asarray(y_dir, float)
    y /= np.linalg.norm(y)
    z = np.asarray(z_dir, float)
    z = z - y * (z @ y)
    z /= np.linalg.norm(z)
    x = np.cross(y, z)
    return mat2quat(np.column_stack([x, y, z]))


def f(*vals: float) -> str:
    return " ".join(f"{v:.6g}" for v in vals)


class Builder:
    """Accumulates bodies, actuators and spec entries for one hand."""

    def __init__(self, name: str):
        self.name = name
        self.joints: list[str] = []
        self.actuators: list[str] = []
        self.act_xml: list[str] = []
        self.ranges: dict[str, tuple[float, float]] = {}
        self.roles: dict[str, str] = {}

    def joint(self, ind: str, jname: str, axis, rng, kp: float, fmax: float, role: str,
              jtype: str = "hinge") -> str:
        self.joints.append(jname)
        aname = "a_" + jname
        self.actuators.append(aname)
        self.ranges[jname] = (float(rng[0]), float(rng[1]))
        self.roles[jname] = role
        self.act_xml.append(
            f'<position name="{aname}" joint="{jname}" kp="{kp:g}" dampratio="1" '
            f'ctrlrange="{f(*rng)}" forcerange="{f(-fmax, fmax)}"/>')
        return f'{ind}<joint name="{jname}" type="{jtype}" axis="{f(*axis)}" range="{f(*rng)}"/>\n'


def chain(b: Builder, ind: str, prefix: str, segs: list[dict], cls: str, mat: str) -> str:
    """A serial finger: each segment is a body (joints + a capsule along +y), the next body sits at its
    end. Flexion is about +x (tip moves toward +z, the palmar side); abduction about +z."""
    if not segs:
        return ""
    s = segs[0]
    name = f"{prefix}{s['name']}"
    out = f'{ind}<body name="{name}" pos="{f(*s.get("pos", (0, 0, 0)))}"'
    if "quat" in s:
        out += f' quat="{f(*s["quat"])}"'
    out += ">\n"
    i2 = ind + "  "
    L, r, m = s["len"], s["rad"], s["mass"]
    # explicit inertial: a solid cylinder of the capsule's size along y
    ixx = m * (3 * r * r + L * L) / 12.0
    iyy = m * r * r / 2.0
    out += f'{i2}<inertial pos="0 {L / 2:.6g} 0" mass="{m:g}" diaginertia="{f(ixx, iyy, ixx)}"/>\n'
    for j in s.get("joints", []):
        out += b.joint(i2, f"{prefix}{j[0]}", j[1], j[2], j[3], j[4], j[5])
    if s.get("knuckle"):
        out += (f'{i2}<geom name="{name}_knuckle" class="visual" type="sphere" '
                f'size="{s["knuckle"]:.6g}" material="{mat}"/>\n')
    if L > 0:
        geom_type = s.get("type", "capsule")
        if geom_type == "box":
            out += (f'{i2}<geom name="{name}_geom" class="{cls}" type="box" pos="0 {L / 2:.6g} 0" '
                    f'size="{f(r, L / 2, s.get("hz", r))}" material="{mat}"/>\n')
        else:
            out += (f'{i2}<geom name="{name}_geom" class="{cls}" type="capsule" '
                    f'fromto="0 0 0 0 {L:.6g} 0" size="{r:.6g}" material="{mat}"/>\n')
    if s.get("tip"):
        tr = s["tip"]
        out += (f'{i2}<geom name="{name}_tip" class="{cls}" type="sphere" '
                f'pos="0 {L:.6g} 0" size="{tr:.6g}" material="{s.get("tipmat", mat)}"/>\n')
    rest = [dict(segs[1], pos=(0, L, 0))] + segs[2:] if len(segs) > 1 else []
    out += chain(b, i2, prefix, rest, cls, mat)
    out += f"{ind}</body>\n"
    return out


def defaults(finger_fric: str = "1 0.02 0.0002") -> str:
    # contype 2 / conaffinity 1: hand geoms collide with the world (contype 1) but not with each other;
    # the thumb (class "thumb": 3/3) also collides with the palm and the other fingers.
    return f"""  <default>
    <default class="hand">
      <joint damping="0.05" armature="0.002" frictionloss="0.005"/>
      <geom contype="2" conaffinity="1" condim="4" friction="{finger_fric}" solref="0.004 1"
            solimp="0.95 0.99 0.001" priority="1"/>
      <default class="visual">
        <geom contype="0" conaffinity="0" group="2" density="0"/>
      </default>
      <default class="thumb">
        <geom contype="3" conaffinity="3"/>
      </default>
    </default>
  </default>
"""


def listed(name: str) -> dict:
    """The hand's ``title`` and ``order`` as its ``spec.json`` holds them (where a hand is listed:
    written there once, kept by every rebuild; the registry, `opend_mj.sim.hands`, reads them)."""
    path = HERE / name / "spec.json"
    old = json.loads(path.read_text()) if path.is_file() else {}
    return {k: old[k] for k in ("title", "order") if k in old}


def write_hand(b: Builder, body_xml: str, spec: dict, rgba: dict[str, str]) -> None:
    folder = HERE / b.name
    folder.mkdir(exist_ok=True)
    mats = "\n".join(f'    <material name="{k}" rgba="{v}" specular="0.3" shininess="0.4"/>'
                     for k, v in rgba.items())
    excl = ""
    if "th_proximal" in body_xml:
        # the thumb's first link starts inside the palm; the thumb collides with the fingers only
        excl = ("  <contact>\n" + "".join(
            f'    <exclude body1="palm" body2="th_{seg}"/>\n'
            for seg in ("proximal", "middle", "distal")) + "  </contact>\n")
    body_xml, touch = add_touch_sites(body_xml)
    sensors = "".join(f'    <touch name="touch_{g}" site="touch_{g}"/>\n' for g, _ in touch)
    xml = f"""<!-- Generated by hands/build_hands.py; edit that file, not this one. -->
<mujoco model="{b.name}">
  <compiler angle="radian" autolimits="true"/>
{defaults()}  <asset>
{mats}
  </asset>
  <worldbody>
{body_xml}  </worldbody>
{excl}  <actuator>
{chr(10).join('    ' + a for a in b.act_xml)}
  </actuator>
  <sensor>
{sensors}  </sensor>
</mujoco>
"""
    (folder / "hand.xml").write_text(xml)
    spec = dict(spec)
    spec.update(name=b.name, **listed(b.name), dof=len(b.joints), joint_names=b.joints, actuator_names=b.actuators,
                joint_ranges={k: list(v) for k, v in b.ranges.items()}, joint_roles=b.roles,
                touch_sensors={f"touch_{g}": part for g, part in touch})
    (folder / "spec.json").write_text(json.dumps(spec, indent=2) + "\n")


#: a touch site is its geom grown by this much (m): a contact on the geom's surface lies inside it
TOUCH_MARGIN = 0.002


def touch_part(geom: str) -> str:
    """Which part of the hand a collision geom belongs to: ``palm``, ``thumb`` or a finger name
    (``ff``, ``mf``, ``rf``, ``lf``, Franka's ``finger_left`` / ``finger_right``)."""
    if geom.startswith("th_"):
        return "thumb"
    if geom.startswith("finger_"):
        return "_".join(geom.split("_")[:2])
    if geom.startswith(("palm", "hand_", "flange", "carpal")) or "metacarpal" in geom:
        return "palm"
    return geom.split("_")[0]


def add_touch_sites(body_xml: str) -> tuple[str, list[tuple[str, str]]]:
    """A touch sensor zone on every named collision geom of the fingers and palm: a site of the same
    shape grown by ``TOUCH_MARGIN`` (MuJoCo's touch sensor sums the normal forces of the contacts
    inside its site). Returns the body XML with the sites and (geom name, part) per site."""
    out, touch = [], []
    for line in body_xml.splitlines(keepends=True):
        out.append(line)
        m = re.match(r'(\s*)<geom name="([^"]+)"(.*)/>', line)
        if not m or 'class="visual"' in line or "knuckle" in m.group(2):
            continue
        ind, name, attrs = m.groups()
        gtype = re.search(r'type="(\w+)"', attrs).group(1)
        size = [float(v) for v in re.search(r'size="([^"]+)"', attrs).group(1).split()]
        if gtype == "box":
            size = [v + TOUCH_MARGIN for v in size]
        else:
            size = [size[0] + TOUCH_MARGIN] + size[1:]
        place = " ".join(f'{k}="{v}"' for k, v in re.findall(r'(pos|fromto|quat)="([^"]+)"', attrs))
        out.append(f'{ind}<site name="touch_{name}" type="{gtype}" {place} size="{f(*size)}" '
                   f'rgba="0 1 0 0.2" group="5"/>\n')
        touch.append((name, touch_part(name)))
    return "".join(out), touch


CONVENTION = ("grasp_site: handle centre in a power grasp. Site (and root) frame: +z = approach "
              "direction (palm -> object; +x world when grasping a cabinet handle), +x = handle long "
              "axis, +y = finger extension direction (Franka: finger closing axis). Root origin = "
              "wrist (Franka: flange).")


def profile(b: Builder, values: dict[str, float]) -> list[float]:
    """Actuator targets from per-role values (roles not listed -> 0), clipped to ranges."""
    out = []
    for j in b.joints:
        lo, hi = b.ranges[j]
        v = values.get(b.roles[j], 0.0)
        out.append(round(float(min(max(v, lo), hi)), 4))
    return out


# --------------------------------------------------------------------------------------------------
# Franka Emika Panda gripper
# --------------------------------------------------------------------------------------------------
def build_franka() -> None:
    """Panda hand: flange-to-fingertip 103.4 mm (TCP), hand body ~ 204 x 63 mm, 0.73 kg; two
    prismatic fingers, 0-40 mm stroke each, 70 N continuous grip force (140 N peak)."""
    b = Builder("franka")
    jf = (0, 0, 0)
    body = '    <body name="palm" childclass="hand">\n'
    body += '      <inertial pos="0 0 0.04" mass="0.73" diaginertia="0.0025 0.0006 0.0024"/>\n'
    body += ('      <geom name="hand_body" type="box" pos="0 0 0.03" size="0.03 0.102 0.027" '
             'material="white"/>\n')
    body += ('      <geom name="hand_cap" type="box" pos="0 0 0.0585" size="0.012 0.1 0.0015" '
             'material="dark"/>\n')
    body += ('      <geom name="flange" type="cylinder" pos="0 0 0.002" size="0.03 0.002" '
             'material="dark"/>\n')
    body += '      <site name="grasp_site" pos="0 0 0.0934" size="0.005" rgba="1 0 0 0.6" group="4"/>\n'
    for side, sgn in (("left", 1), ("right", -1)):
        jn = f"finger_{side}"
        body += f'      <body name="{jn}" pos="0 0 0.0584">\n'
        body += ('        <inertial pos="0 {0:.4g} 0.025" mass="0.015" '
                 'diaginertia="3e-6 3e-6 1e-6"/>\n').format(sgn * 0.012)
        body += b.joint("        ", f"{jn}_joint", (0, sgn, 0), (0, 0.04), 10000, 70, "finger",
                        jtype="slide").replace('"/>', '" armature="0.1" damping="5"/>')
        # finger body and rubber pad; the pad's inner face is at y = +-opening
        body += (f'        <geom name="{jn}_link" type="box" pos="0 {sgn * 0.0125:.4g} 0.022" '
                 f'size="0.0105 0.0085 0.022" material="white"/>\n')
        body += (f'        <geom name="{jn}_pad" type="box" pos="0 {sgn * 0.004:.4g} 0.035" '
                 f'size="0.0095 0.004 0.0095" material="pad" friction="1.2 0.02 0.0002"/>\n')
        body += "      </body>\n"
    body += "    </body>\n"
    del jf
    spec = dict(
        hand_type="parallel_gripper", root_body="palm", grasp_site="grasp_site",
        grasp_site_pos=[0, 0, 0.0934], grasp_site_quat=[1, 0, 0, 0], convention=CONVENTION,
        open_pose=[0.04, 0.04],
        grasp_profiles={"horizontal": [0.0, 0.0], "vertical": [0.0, 0.0]},
        pregrasp_profiles={"horizontal": [0.04, 0.04], "vertical": [0.04, 0.04]},
        approach_offset=0.0, close_time=0.4, mass=0.76,
        notes="Fingers close along the site's y axis; target 0 squeezes with the 70 N force limit.")
    write_hand(b, body, spec, {"white": "0.92 0.92 0.92 1", "dark": "0.15 0.15 0.15 1",
                               "pad": "0.1 0.1 0.1 1"})


# --------------------------------------------------------------------------------------------------
# Dexterous hands: shared layout
# --------------------------------------------------------------------------------------------------
def finger_segs(links, radii, masses, *, abd_range, flex_ranges, kps, fmaxs, separate_base=None,
                tip=None, knuckles=None):
    """Segments for a 4-DoF finger: abduction + 3 flexions. ``separate_base``: length of a separate
    abduction link (Allegro); otherwise abduction and MCP flexion form one two-axis joint."""
    names = ["proximal", "middle", "distal"]
    segs = []
    if separate_base:
        segs.append(dict(name="base", len=separate_base, rad=radii[0], mass=masses[0] * 0.4,
                         type="box", hz=radii[0],
                         joints=[("abd", (0, 0, 1), abd_range, kps[0], fmaxs[0], "abd")]))
    for i in range(3):
        joints = []
        if i == 0 and not separate_base:
            joints.append(("abd", (0, 0, 1), abd_range, kps[0], fmaxs[0], "abd"))
        role = ["mcp", "pip", "dip"][i]
        joints.append((role, (1, 0, 0), flex_ranges[i], kps[i + 1], fmaxs[i + 1], role))
        seg = dict(name=names[i], len=links[i], rad=radii[i], mass=masses[i], joints=joints)
        if knuckles:
            seg["knuckle"] = knuckles[i]
        segs.append(seg)
    if tip:
        segs[-1]["tip"] = tip
    return segs


def dexterous(b: Builder, *, palm_xml: str, palm_mass: float, palm_inertia, fingers: list[dict],
              thumb: dict, grasp_site_pos, mat: str, cls_f="hand") -> str:
    body = '    <body name="palm" childclass="hand">\n'
    body += (f'      <inertial pos="0 {grasp_site_pos[1] * 0.6:.4g} -0.01" mass="{palm_mass:g}" '
             f'diaginertia="{f(*palm_inertia)}"/>\n')
    body += palm_xml
    body += (f'      <site name="grasp_site" pos="{f(*grasp_site_pos)}" size="0.005" '
             f'rgba="1 0 0 0.6" group="4"/>\n')
    for fd in fingers:
        segs = [dict(s) for s in fd["segs"]]
        segs[0]["pos"] = fd["pos"]
        if "quat" in fd:
            segs[0]["quat"] = fd["quat"]
        body += chain(b, "      ", fd["prefix"], segs, fd.get("cls", cls_f), mat)
    # thumb: a base body on the palm edge with the opposition hinge (about the palm's y axis),
    # then the finger frame rotated to the thumb's rest direction.
    t = thumb
    body += f'      <body name="{t["prefix"]}base" pos="{f(*t["pos"])}">\n'
    body += ('        <inertial pos="0 0 0" mass="{0:g}" diaginertia="{1:.3g} {1:.3g} {1:.3g}"/>\n'
             .format(t["base_mass"], t["base_mass"] * 1e-4))
    body += b.joint("        ", f'{t["prefix"]}opp', t["opp_axis"], t["opp_range"], t["kps"][0],
                    t["fmaxs"][0], "thumb_opp")
    if t.get("base_geom"):
        body += "        " + t["base_geom"] + "\n"
    segs = [dict(s) for s in t["segs"]]
    segs[0]["quat"] = t["rest_quat"]
    body += chain(b, "        ", t["prefix"], segs, "thumb", mat)
    body += "      </body>\n"
    body += "    </body>\n"
    return body


def thumb_segs(links, radii, masses, kps, fmaxs, ranges, tip=None, knuckles=None):
    """Thumb after the opposition hinge: abduction (about the thumb's palmar normal) + MCP + IP."""
    segs = [dict(name="proximal", len=links[0], rad=radii[0], mass=masses[0],
                 joints=[("abd", (0, 0, 1), ranges[0], kps[1], fmaxs[1], "thumb_abd"),
                         ("mcp", (1, 0, 0), ranges[1], kps[2], fmaxs[2], "thumb_mcp")]),
            dict(name="middle", len=links[1], rad=radii[1], mass=masses[1],
                 joints=[("ip", (1, 0, 0), ranges[2], kps[3], fmaxs[3], "thumb_ip")]),
            dict(name="distal", len=links[2], rad=radii[2], mass=masses[2])]
    if tip:
        segs[-1]["tip"] = tip
    if knuckles:
        for s, k in zip(segs, knuckles):
            s["knuckle"] = k
    return segs


def thumb_rest(side: float):
    """Thumb rest frame: pointing out sideways and forward in the palm plane, palmar side toward the
    fingers; the opposition hinge then swings it in front of the palm (+z)."""
    return frame_quat((side * 0.75, 0.66, 0.0), (-side * 0.66, 0.75, 0.0))


# --------------------------------------------------------------------------------------------------
def build_allegro() -> None:
    """Allegro Hand (Wonik): 4 fingers x 4 joints; finger links 54 / 38.4 / 26.7 mm + 17 mm tip
    (distal + tip ~ 44 mm), base (abduction) link 16.4 mm, link width 19.6 mm, finger spacing
    45.4 mm, palm ~ 95 mm wide; total mass 1.08 kg; joint torque ~ 0.7 N m."""
    b = Builder("allegro")
    r = 0.0098
    kp = (3.0, 3.0, 3.0, 3.0)
    fm = (0.7, 0.7, 0.7, 0.7)
    flex = [(-0.2, 1.6), (-0.17, 1.7), (-0.23, 1.6)]
    y_mcp = 0.095
    fingers = []
    for i, (nm, x) in enumerate((("ff", 0.0454), ("mf", 0.0), ("rf", -0.0454))):
        segs = finger_segs((0.054, 0.0384, 0.0267), (r, r, r), (0.055, 0.03, 0.02),
                           abd_range=(-0.47, 0.47), flex_ranges=flex, kps=kp, fmaxs=fm,
                           separate_base=0.0164, tip=0.012)
        fingers.append(dict(prefix=f"{nm}_", pos=(x, y_mcp, -r), segs=segs))
    palm_xml = ('      <geom name="palm_geom" type="box" pos="0 0.0475 -0.0204" '
                'size="0.0475 0.0475 0.0204" material="black"/>\n'
                '      <geom name="palm_cover" class="visual" type="box" pos="0 0.0475 -0.0005" '
                'size="0.046 0.046 0.0008" material="gray"/>\n')
    thumb = dict(prefix="th_", pos=(0.05, 0.025, -0.012), opp_axis=(0, -1, 0), opp_range=(0, 1.6),
                 kps=(4.0, 3.0, 3.0, 3.0), fmaxs=(0.9, 0.7, 0.7, 0.7), base_mass=0.03,
                 rest_quat=thumb_rest(1.0),
                 base_geom='<geom type="box" size="0.012 0.012 0.012" material="black"/>',
                 segs=thumb_segs((0.0554, 0.0514, 0.0423), (r, r, r), (0.055, 0.04, 0.03),
                                 (3.0, 3.0, 3.0, 3.0), (0.7, 0.7, 0.7, 0.7),
                                 [(-0.3, 1.2), (-0.19, 1.6), (-0.16, 1.7)], tip=0.012))
    for fd in fingers:
        fd["segs"][0]["type"] = "box"
    site = (0.0, y_mcp + 0.054 - 0.02, 0.0085)
    body = dexterous(b, palm_xml=palm_xml, palm_mass=0.45, palm_inertia=(1.2e-3, 6e-4, 1.5e-3),
                     fingers=fingers, thumb=thumb, grasp_site_pos=site, mat="black")
    write_dex(b, body, site, dict(mcp=0.25, pip=1.6, dip=1.3, thumb_opp=1.5, thumb_abd=0.2,
                                  thumb_mcp=0.9, thumb_ip=0.9),
              {"black": "0.12 0.12 0.13 1", "gray": "0.5 0.5 0.52 1"}, mass=1.08,
              notes="Allegro: ff/mf/rf = index/middle/ring (abd, mcp, pip, dip); thumb = opp, abd, "
                    "mcp, ip. Real Allegro proportions; 0.7 N m joint torque limit.")


def write_dex(b, body, site, close, mats, mass, notes, open_=None):
    open_vals = open_ or {}
    spec = dict(
        hand_type="dexterous", root_body="palm", grasp_site="grasp_site",
        grasp_site_pos=[round(v, 5) for v in site], grasp_site_quat=[1, 0, 0, 0],
        convention=CONVENTION,
        open_pose=profile(b, dict({"thumb_opp": 0.35}, **open_vals)),
        grasp_profiles={"horizontal": profile(b, close), "vertical": profile(b, close)},
        pregrasp_profiles={"horizontal": profile(b, open_vals), "vertical": profile(b, open_vals)},
        approach_offset=0.0, close_time=0.5, mass=mass, notes=notes)
    write_hand(b, body, spec, mats)


# --------------------------------------------------------------------------------------------------
def build_shadow() -> None:
    """Shadow Dexterous Hand (no forearm): wrist-to-knuckle 95 mm, palm ~ 84 x 22 mm (finger spacing
    22 mm), finger phalanges 45 / 25 / 26 mm, thumb 38 / 32 / 27.5 mm, finger radius ~ 9-10 mm.
    20 DoF as in the paper (10 revolute + 5 two-axis): each finger abd+mcp (two-axis), pip, dip;
    thumb opposition+abduction (two-axis CMC), mcp, ip. The real hand's little-finger metacarpal
    and thumb's extra joint are left out, and the distal joints are actuated on their own."""
    b = Builder("shadow")
    y_mcp = 0.095
    fingers = []
    specs = (("ff", 0.033, 0.0), ("mf", 0.011, 0.004), ("rf", -0.011, 0.0), ("lf", -0.033, -0.008))
    for nm, x, dy in specs:
        segs = finger_segs((0.045, 0.025, 0.018), (0.0095, 0.009, 0.0085), (0.03, 0.015, 0.01),
                           abd_range=(-0.35, 0.35), flex_ranges=[(-0.26, 1.57), (0, 1.57), (0, 1.57)],
                           kps=(4.0, 5.0, 4.0, 3.0), fmaxs=(1.0, 1.5, 1.0, 0.8), tip=0.0085)
        fingers.append(dict(prefix=f"{nm}_", pos=(x, y_mcp + dy, -0.0095), segs=segs))
    palm_xml = ('      <geom name="palm_geom" type="box" pos="0 0.0475 -0.011" '
                'size="0.042 0.0475 0.011" material="black"/>\n'
                '      <geom name="wrist_geom" type="capsule" fromto="-0.03 0 -0.011 0.03 0 -0.011" '
                'size="0.018" material="black"/>\n'
                '      <geom name="palm_pad" class="visual" type="ellipsoid" pos="0 0.05 -0.002" '
                'size="0.038 0.042 0.006" material="pad"/>\n')
    thumb = dict(prefix="th_", pos=(0.036, 0.03, -0.012), opp_axis=(0, -1, 0), opp_range=(0, 1.57),
                 kps=(5.0, 4.0, 4.0, 3.0), fmaxs=(1.5, 1.0, 1.0, 0.8), base_mass=0.02,
                 rest_quat=thumb_rest(1.0),
                 base_geom='<geom class="thumb" type="sphere" size="0.012" material="black"/>',
                 segs=thumb_segs((0.038, 0.032, 0.02), (0.011, 0.01, 0.009), (0.03, 0.02, 0.012),
                                 (5.0, 4.0, 4.0, 3.0), (1.5, 1.0, 1.0, 0.8),
                                 [(-0.5, 0.5), (0, 1.2), (-0.26, 1.57)], tip=0.009))
    site = (0.0, y_mcp + 0.045 - 0.018, 0.0085)
    body = dexterous(b, palm_xml=palm_xml, palm_mass=0.35, palm_inertia=(9e-4, 3e-4, 1.1e-3),
                     fingers=fingers, thumb=thumb, grasp_site_pos=site, mat="skin")
    write_dex(b, body, site, dict(mcp=0.35, pip=1.57, dip=1.4, thumb_opp=1.45, thumb_abd=0.0,
                                  thumb_mcp=0.9, thumb_ip=0.9),
              {"black": "0.1 0.1 0.1 1", "skin": "0.2 0.2 0.22 1", "pad": "0.45 0.45 0.48 1"}, mass=0.75,
              notes="Shadow: ff/mf/rf/lf = first/middle/ring/little (abd+mcp two-axis, pip, dip); "
                    "thumb = opp+abd two-axis CMC, mcp, ip.")


# --------------------------------------------------------------------------------------------------
def build_skeleton() -> None:
    """A hand modelled on human bones (adult male, hand length ~ 19 cm): metacarpals index 68,
    middle 65, ring 58, little 53, thumb 46 mm; proximal phalanges 40 / 45 / 42 / 33 (thumb 32);
    middle 23 / 27 / 26 / 18; distal 17 / 18 / 18 / 16 (thumb 25) mm. Bones are thin capsules
    (radius 4-6 mm) with knuckle spheres; the palm is the metacarpals plus a carpal cluster, no
    flesh. 20 DoF: each finger abd+mcp (two-axis), pip, dip; thumb cmc (two-axis), mcp, ip."""
    b = Builder("skeleton")
    fingers = []
    # name, x at knuckle, metacarpal length, proximal, middle, distal
    bones = (("ff", 0.026, 0.068, 0.040, 0.023, 0.017), ("mf", 0.008, 0.065, 0.045, 0.027, 0.018),
             ("rf", -0.010, 0.058, 0.042, 0.026, 0.018), ("lf", -0.027, 0.053, 0.033, 0.018, 0.016))
    carpal_y = 0.028
    meta_xml = ""
    y_mcp_mid = carpal_y + 0.065
    for nm, x, meta, p, m, d in bones:
        y_k = carpal_y + meta * 0.97
        base_x = x * 0.55
        meta_xml += (f'      <geom name="{nm}_metacarpal" type="capsule" '
                     f'fromto="{f(base_x, carpal_y, -0.005, x, y_k, -0.005)}" size="0.0055" '
                     f'material="bone"/>\n')
        segs = finger_segs((p, m, d), (0.0055, 0.0048, 0.0042), (0.025, 0.012, 0.007),
                           abd_range=(-0.35, 0.35), flex_ranges=[(-0.3, 1.57), (0, 1.75), (0, 1.4)],
                           kps=(4.0, 5.0, 4.0, 3.0), fmaxs=(1.0, 1.5, 1.0, 0.8), tip=0.0055,
                           knuckles=(0.0085, 0.0068, 0.0058))
        fingers.append(dict(prefix=f"{nm}_", pos=(x, y_k, -0.005), segs=segs))
    carpals = ""
    for i, (cx, cy) in enumerate(((-0.012, 0.012), (0.0, 0.012), (0.012, 0.012), (0.022, 0.014),
                                  (-0.016, 0.024), (-0.004, 0.025), (0.008, 0.025), (0.02, 0.027))):
        carpals += (f'      <geom name="carpal_{i}" type="sphere" pos="{f(cx, cy, -0.006)}" '
                    f'size="0.0075" material="bone"/>\n')
    radius_ulna = ('      <geom name="radius_end" class="visual" type="capsule" '
                   'fromto="0.012 -0.02 -0.006 0.012 0.0 -0.006" size="0.009" material="bone"/>\n'
                   '      <geom name="ulna_end" class="visual" type="capsule" '
                   'fromto="-0.012 -0.02 -0.006 -0.012 0.0 -0.006" size="0.007" material="bone"/>\n')
    palm_xml = meta_xml + carpals + radius_ulna
    thumb = dict(prefix="th_", pos=(0.026, 0.02, -0.006), opp_axis=(0, -1, 0), opp_range=(0, 1.57),
                 kps=(5.0, 4.0, 4.0, 3.0), fmaxs=(1.5, 1.0, 1.0, 0.8), base_mass=0.01,
                 rest_quat=thumb_rest(1.0),
                 base_geom='<geom class="thumb" type="sphere" size="0.0085" material="bone"/>',
                 segs=thumb_segs((0.046, 0.032, 0.025), (0.006, 0.0055, 0.0048),
                                 (0.03, 0.015, 0.008), (5.0, 4.0, 4.0, 3.0), (1.5, 1.0, 1.0, 0.8),
                                 [(-0.5, 0.5), (-0.2, 1.2), (-0.2, 1.4)], tip=0.0055,
                                 knuckles=(0.0085, 0.007, 0.006)))
    site = (0.0, y_mcp_mid + 0.045 - 0.015, 0.0075)
    body = dexterous(b, palm_xml=palm_xml, palm_mass=0.25, palm_inertia=(4e-4, 1.5e-4, 5e-4),
                     fingers=fingers, thumb=thumb, grasp_site_pos=site, mat="bone")
    write_dex(b, body, site, dict(mcp=0.35, pip=1.75, dip=1.3, thumb_opp=1.45, thumb_abd=0.0,
                                  thumb_mcp=0.9, thumb_ip=0.9),
              {"bone": "0.93 0.89 0.78 1"}, mass=0.45,
              notes="Skeleton: human bone proportions; ff/mf/rf/lf = index/middle/ring/little "
                    "(abd+mcp two-axis, pip, dip); thumb = cmc opp+abd, mcp, ip.")


def write_readme(name: str, source_doc: str) -> None:
    """``hands/<name>/README.md``: where the dimensions come from, the joints and the actuators."""
    spec = json.loads((HERE / name / "spec.json").read_text())
    doc = " ".join(source_doc.split())
    joints = "\n".join(f"| `{j}` | {spec['joint_roles'].get(j, '')} | {lo:.3g} .. {hi:.3g} |"
                       for j, (lo, hi) in ((j, spec["joint_ranges"][j]) for j in spec["joint_names"]))
    lines = [
        f"# {spec.get('title') or name}: {spec['dof']} finger DoF + 6 DoF root",
        "",
        "Generated by `hands/build_hands.py` (run `python hands/build_hands.py`); edit that file, not the",
        "XML. Written here with primitive geoms from published dimensions; nothing is copied from other",
        "model files.",
        "",
        f"**Dimensions.** {doc}",
        "",
        "**Files.** `hand.xml` (the hand, no freejoint), `scene.xml` (includes `hand.xml`, adds a floor and a",
        f"light: `python -m mujoco.viewer --mjcf hands/{name}/scene.xml`), `spec.json` (grasp site, poses,",
        "grasp profiles), `grasp.json` where the grasp search wrote one, `planner.json` (the planner's numbers "
        "for this hand: docs/planner.md), `render.png`, `CHANGELOG.md` (what changed in these files). All of them "
        "are read through one `HandModel` (`opend_mj.sim.hands.get_hand`).",
        "",
        f"**Touch.** {len(spec.get('touch_sensors', {}))} MuJoCo `touch` sensors, one per collision geom of the "
        "fingers, thumb and palm (site `touch_<geom>`: the geom grown by 2 mm); `spec.json` "
        "`touch_sensors` names the part of each (" + ", ".join(sorted(set(spec.get("touch_sensors", {}).values())))
        + "). The planner reads touch per part as the hand's own state (is it holding? did it slip?): the "
        "normal forces of the contacts on these geoms, less the hand's own contacts (a thumb pressing on a finger).",
        "",
        f"**Root.** Body `{spec['root_body']}`; in the task it gets a freejoint and a soft weld to a mocap body",
        "(`opend_mj.sim.hands.attach_with_mocap`), so the root moves only through the mocap. Grasp site",
        f"`{spec['grasp_site']}` at {spec['grasp_site_pos']} in the root frame. Mass {spec.get('mass', '?')} kg.",
        "",
        f"**Actuators.** {len(spec['actuator_names'])} position actuators, one per joint, in this order: "
        + ", ".join(f"`{a}`" for a in spec["actuator_names"]) + ".",
        "",
        "| joint | role | range (rad or m) |",
        "|---|---|---|",
        joints,
        "",
    ]
    if spec.get("notes"):
        lines[8:8] = [f"**Notes.** {spec['notes']}", ""]
    (HERE / name / "README.md").write_text("\n".join(lines))


#: The hands this file generates, by name (each one's title and order: its ``spec.json``).
BUILDERS = {"franka": build_franka, "allegro": build_allegro, "shadow": build_shadow, "skeleton": build_skeleton}


if __name__ == "__main__":
    from opend_mj.sim.hands import list_hands
    from opend_mj.sim.hands.scene import write_scene_xml

    known = list_hands()  # the registry's order; a hand whose folder is not there yet comes last
    for n in sorted(BUILDERS, key=lambda h: known.index(h) if h in known else len(known)):
        build = BUILDERS[n]
        build()
        write_scene_xml(n, HERE / n / "scene.xml")
        write_readme(n, build.__doc__ or "")
        print(n, json.loads((HERE / n / "spec.json").read_text())["dof"])
