"""Robot hands, one home: a hand is one :class:`HandModel` (``get_hand(name)``) that carries all of
``hands/<name>/``; this package reads those files and nothing else does.

Modules: :mod:`.spec` (``spec.json``: :class:`HandSpec`, grasp-site <-> root poses), :mod:`.settings`
(``grasp.json``, ``planner.json``), :mod:`.registry` (:class:`HandModel`, :func:`get_hand`,
:func:`register_hand`), :mod:`.entity` (the dm_control entity, the mocap weld, touch), :mod:`.scene`
(standalone scenes, ``scene.xml``, the bar-pull trial).

Four hands ship in ``hands/<name>/`` (``hand.xml``, ``spec.json``, ``grasp.json``, ``planner.json``,
``scene.xml``, ``render.png``, ``README.md``, ``CHANGELOG.md``):
``franka`` (2 DoF), ``allegro`` (16), ``shadow`` (20), ``skeleton`` (20). ``hands/build_hands.py``
generates the MJCF and specs from published dimensions (primitive geoms only). The registry finds
them by their folders (``$OPEND_HANDS_DIR`` names another folder of hands); each ``spec.json`` holds
the hand's ``title`` and ``order``, so a hand is added by adding its folder.

Conventions (world: z up, metres; cabinets face -x, the hand approaches handles moving along +x):

* Every hand has a site ``grasp_site``: where the handle centre sits in a power grasp.
  Its **+z axis is the approach direction** (palm -> object; +x world when grasping a cabinet
  handle), its **+x axis is the handle's long axis**, +y = z cross x (the direction the open fingers
  extend; for the Franka gripper the finger-closing axis).
* The hand's root body (``spec.root_body``, the wrist / flange) has the same orientation as the grasp
  site in all four built-in hands; the site sits at ``spec.grasp_site_pos`` in the root frame.
  User hands may declare any fixed offset (``grasp_site_pos``, ``grasp_site_quat``).
* ``orientation_for_handle("horizontal")``: site +x = +y world, +z = +x world (fingers point up).
  ``orientation_for_handle("vertical")``: site +x = -z world, +z = +x world (fingers point +y).
* The hand MJCF has no freejoint or mocap body. ``attach_with_mocap`` adds both to an arena: the
  hand gets a freejoint and a soft weld to a mocap body; the root only ever moves through the mocap
  body after reset (``MocapHandle.reset_pose`` places both together, ``MocapHandle.move`` moves the
  mocap target only).
* Finger actuators are position actuators, one per joint, in ``spec.actuator_names`` order;
  ``spec.open_pose`` and ``spec.grasp_profiles[...]`` are targets in that order.

Quaternions are (w, x, y, z) as in MuJoCo.
"""

from opend_mj.sim.hands.entity import (
    WELD_SOLIMP,
    WELD_SOLREF,
    Hand,
    HandTouch,
    MocapHandle,
    attach_with_mocap,
    touch_dict,
    touch_geoms,
    touch_parts,
)
from opend_mj.sim.hands.registry import (
    HANDS_DIR,
    HANDS_DIR_ENV,
    HandModel,
    builtin_hands,
    find_hands,
    get_hand,
    hands_folder,
    list_hands,
    load_hand_folder,
    load_spec,
    register_hand,
)
from opend_mj.sim.hands.settings import (
    GRASP_FILE,
    PLANNER_FILE,
    GraspProfile,
    HandPlannerConfig,
)
from opend_mj.sim.hands.spec import (
    HandSpec,
    grasp_pose_to_root_pose,
    orientation_for_handle,
    root_pose_to_grasp_pose,
)

__all__ = [
    "GRASP_FILE", "HANDS_DIR", "HANDS_DIR_ENV", "PLANNER_FILE", "WELD_SOLIMP", "WELD_SOLREF", "GraspProfile",
    "Hand", "HandModel", "HandPlannerConfig", "HandSpec", "HandTouch", "MocapHandle",
    "attach_with_mocap", "builtin_hands", "find_hands", "get_hand", "grasp_pose_to_root_pose", "hands_folder",
    "list_hands", "load_hand_folder", "load_spec", "orientation_for_handle", "register_hand", "root_pose_to_grasp_pose", "touch_dict", "touch_geoms",
    "touch_parts",
]
