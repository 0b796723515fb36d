"""The procedural generator's configuration: sizes, handle population and every probability."""

from __future__ import annotations

from dataclasses import dataclass


from opend_mj.assets.layout import PARTNET_SCALE


#: Bumped whenever the generated geometry changes.
GENERATOR_VERSION = "6"

HANDLE_KINDS = ("bar", "arched", "knob")


@dataclass(frozen=True)
class GeneratorConfig:
    """Knobs of the procedural generator (lengths in real metres)."""

    scale: float = PARTNET_SCALE
    #: Target fraction of cabinets that the language rule cannot describe (as in OpenD: 172/346).
    invalid_fraction: float = 0.5
    #: Gap between a movable part and every carcass panel / neighbouring movable part.
    clearance: float = 0.004
    #: Sides of every handle cylinder.
    cylinder_sides: int = 16
    #: Decimals written for every float (determinism and file size).
    decimals: int = 6
    #: Language rule: handle centres closer than this (m) form one level / one column position.
    level_tolerance: float = 0.04
    #: Language rule: at most this many vertical levels and horizontal positions can be named.
    max_levels: int = 5
    width_range: tuple[float, float] = (0.3, 1.2)
    height_range: tuple[float, float] = (0.3, 1.8)
    depth_range: tuple[float, float] = (0.3, 0.6)
    thickness_range: tuple[float, float] = (0.015, 0.020)
    #: Handle population, matched to the real OpenD training cabinets as the planner measures them in
    #: depth (``tools/handle_stats.py``; real 10th / 50th / 90th percentiles: bar thickness 6.6 / 12.3 /
    #: 16.9 mm, stand-off gap 9.6 / 23.1 / 34.8 mm, bar length 57 / 154 / 542 mm, knobs 4 %, knob size
    #: 37 / 41 / 44 mm).
    bar_diameter_range: tuple[float, float] = (0.005, 0.021)
    bar_gap_range: tuple[float, float] = (0.008, 0.038)
    #: Probabilities of (bar, arched, knob) per target type.
    drawer_handle_kinds: tuple[float, float, float] = (0.70, 0.24, 0.06)
    door_handle_kinds: tuple[float, float, float] = (0.70, 0.24, 0.06)
    #: Share of straight bars that run most of their panel (long door pulls, full-width drawer bars).
    long_bar_share: float = 0.35
    long_bar_max: float = 0.80
    #: A long bar's length between this fraction of its longest and the longest (real long pulls span
    #: most of their panel).
    long_bar_min_frac: float = 0.6
    short_bar_min: float = 0.05
    #: Wide drawers (front wider than ``paired_pull_min_width``) carry two pulls, one per half, this often.
    paired_pull_share: float = 0.35
    paired_pull_min_width: float = 0.55
    knob_cap_radius_range: tuple[float, float] = (0.017, 0.023)
    #: Door handles sit this far (m) from the door's free edge (double doors: handles 3-12 cm apart).
    door_handle_margin_range: tuple[float, float] = (0.015, 0.06)
    #: Door handles that are horizontal bars (real side-hinged doors of the OpenD training cabinets:
    #: 47 of 126). Of those, the real ones sit along the door's top edge (34 of
    #: 47; else along its bottom edge, as on wall units), 2-5 cm from it, centred across the door
    #: about half of the time (24 of 47; else near its free edge).
    door_horizontal_share: float = 0.37
    door_bar_top_share: float = 0.72
    door_bar_centred_share: float = 0.5
    door_bar_edge_range: tuple[float, float] = (0.03, 0.06)
    #: Flaps: doors hinged about a horizontal axis along their top edge (they lift up) or bottom edge
    #: (they drop down), each with a horizontal bar along its free edge. The real OpenD training
    #: cabinets: 18 of 144 doors in 10 cabinets, 8 hinged at the top and 10 at the bottom, opening
    #: 90-114 degrees, side by side in pairs in 4 of them. ``flap_share`` is the share of cabinets with
    #: doors whose doors are all flaps; drawn from a random stream of its own.
    flap_share: float = 0.25
    #: Doors taller than this (m) stay side-hinged (the real flaps are 0.25-0.91 m tall).
    flap_max_height: float = 0.95
    flap_top_share: float = 0.45
    flap_top_range: tuple[float, float] = (1.57, 1.75)
    flap_bottom_range: tuple[float, float] = (1.57, 1.75)
    #: A horizontal door bar not centred across its door ends this far (m) from the door's free edge;
    #: on double doors and flap pairs the two pulls stand side by side (the real 10th percentile of the
    #: free space from a handle to the nearest other one is 5 mm).
    door_bar_end_margin_range: tuple[float, float] = (0.004, 0.025)
    #: How a cabinet meets the floor, as shares of (bottom fronts down to the floor, fronts inset above
    #: the bottom panel, a low plinth in ``low_plinth_range``, a plinth or legs in ``plinth_range``).
    #: Matched to the real OpenD training cabinets' lowest moving part above the floor (the feasibility
    #: check's figure, 133 cabinets): 18 % within 5 mm, 16 % 0.5-5 cm, 4 % 5-10 cm, 62 % 10-22 cm.
    base_shares: tuple[float, float, float, float] = (0.18, 0.16, 0.05, 0.61)
    low_plinth_range: tuple[float, float] = (0.03, 0.08)
    plinth_range: tuple[float, float] = (0.08, 0.18)

    # Probabilities of the sampled choices (each a share of cabinets, or of the targets or handles
    # named). Weights of a list need not sum to one: they are normalised where they are drawn.
    #: Fronts painted like the carcass; interiors painted like it (else a light wood tone); handles
    #: in the front's colour (else a metal or plastic finish).
    front_matches_body_share: float = 0.7
    interior_matches_body_share: float = 0.5
    body_coloured_handle_share: float = 0.15
    #: Carcass palettes and their weights (colours in `materials.PALETTES`).
    palette_weights: tuple[tuple[str, float], ...] = (
        ("wood", 0.4), ("white", 0.2), ("grey", 0.15), ("black", 0.08), ("colour", 0.17))
    #: Layout families (`layouts.sample_layout`) and their weights: describable ones, and ones that the
    #: language rule cannot describe (drawn with probability ``invalid_fraction``).
    valid_layouts: tuple[tuple[str, float], ...] = (
        ("single_drawer", 0.16), ("drawer_stack", 0.14), ("drawer_grid", 0.04), ("single_door", 0.22),
        ("double_door", 0.19), ("drawers_over_doors", 0.08), ("door_beside_drawers", 0.04), ("wardrobe", 0.04),
        ("double_door_rows", 0.04), ("stacked_doors", 0.05))
    invalid_layouts: tuple[tuple[str, float], ...] = (
        ("tall_drawer_stack", 0.6), ("drawer_row", 0.2), ("stack_beside_door", 0.2))
    #: Drawer stacks graduated (deeper drawers at the bottom).
    graduated_stack_share: float = 0.4
    #: Single-drawer cabinets that are nightstands (a drawer over an open shelf).
    nightstand_share: float = 0.5
    #: Drawers per stack of the ``drawer_stack`` family, and per stack beside a door, with weights.
    drawer_stack_sizes: tuple[tuple[int, float], ...] = ((2, 0.55), (3, 0.3), (4, 0.1), (5, 0.05))
    door_beside_stack_sizes: tuple[tuple[int, float], ...] = ((2, 0.5), (3, 0.35), (4, 0.15))
    #: (columns, rows) of the ``drawer_grid`` family, with weights.
    drawer_grid_shapes: tuple[tuple[tuple[int, int], float], ...] = (
        ((2, 1), 0.5), ((2, 2), 0.25), ((3, 1), 0.15), ((2, 3), 0.1))
    #: Single doors hinged on the left (beside a drawer stack: the door on the left).
    left_hinge_share: float = 0.5
    #: Wide drawers-over-doors cabinets with two drawers side by side on top.
    paired_top_drawers_share: float = 0.4
    #: Doors of the cabinet with the drawers' handle kind (else drawn on their own).
    shared_handle_kind_share: float = 0.7
    #: Tall doors (over 45 cm) with an inner shelf behind them.
    door_shelf_share: float = 0.6
    #: Drawer bars that run vertically; square bars (else round); U-shaped arches (else trapezoids);
    #: knobs with a rim plate against the panel.
    drawer_vertical_share: float = 0.12
    square_bar_share: float = 0.25
    u_arch_share: float = 0.5
    knob_rim_share: float = 0.4
