import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from dm_control import mjcf  # noqa: E402

from opend_mj.sim.camera import RGBDCamera, geom_box_corners, place_camera  # noqa: E402
from opend_mj.sim.rooms import ROOM_NAMES, KeepOut, RoomArena  # noqa: E402

BOX = (0.25, 0.45, 1.2)  # half x, half y, height of the stand-in cabinet


def build(room, seed, light_scale=1.0, keepout=None):
    arena = RoomArena(room, seed, light_scale=light_scale, keepout=keepout)
    hx, hy, h = BOX
    arena.mjcf_model.worldbody.add("geom", name="standin", type="box", pos=[0, 0, h / 2], size=[hx, hy, h / 2], rgba=[0.5, 0.5, 0.5, 1])
    arena.add_camera(place_camera([-hx, -hy, 0], [hx, hy, h]), name="front")
    physics = mjcf.Physics.from_mjcf_model(arena.mjcf_model)
    physics.forward()
    return arena, physics


def render(physics, size=64):
    with RGBDCamera(physics, "front", size, size) as cam:
        return cam.render_rgb()


def test_room_names():
    assert len(ROOM_NAMES) == 9 and len(set(ROOM_NAMES)) == 9


@pytest.mark.parametrize("room", range(9))
def test_room_compiles_and_renders(room):
    arena, physics = build(room, seed=room)
    m = physics.model.ptr
    from opend_mj.sim.physics import PHYSICS

    assert m.opt.timestep == pytest.approx(PHYSICS.timestep)  # the project's options, one definition
    assert m.opt.impratio == pytest.approx(PHYSICS.impratio) and m.opt.cone == 1  # elliptic
    assert m.vis.global_.offwidth >= 640 and m.vis.global_.offheight >= 480
    with RGBDCamera(physics, "front", 256, 256) as cam:
        rgb = cam.render_rgb()
    assert rgb.shape == (256, 256, 3) and rgb.dtype == np.uint8
    assert rgb.std() > 5 and 20 < rgb.mean() < 240
    # The room has furniture, and the floor is the only colliding geom of the arena.
    assert len(arena.furniture) >= 3
    floor_id = physics.bind(arena.floor).element_id
    for g in arena.decoration_geoms:
        gid = physics.bind(g).element_id
        assert m.geom_contype[gid] == 0 and m.geom_conaffinity[gid] == 0
    assert m.geom_contype[floor_id] == 1


def test_same_seed_same_image_different_seed_differs():
    a = render(build(2, 7)[1])
    b = render(build(2, 7)[1])
    c = render(build(2, 8)[1])
    np.testing.assert_array_equal(a, b)
    assert np.abs(a.astype(int) - c.astype(int)).mean() > 1.0


def test_low_light_is_darker():
    for room in (1, 5):
        bright = render(build(room, 3, 1.0)[1]).astype(float).mean()
        dark = render(build(room, 3, 0.7)[1]).astype(float).mean()
        assert dark < 0.9 * bright


@pytest.mark.parametrize("keepout", [KeepOut(), KeepOut(zone_x=0.6, zone_y=1.0, zone_z=2.2)])
def test_decoration_never_enters_keepout(keepout):
    for room in range(9):
        for seed in (0, 1):
            arena = RoomArena(room, seed, keepout=keepout)
            physics = mjcf.Physics.from_mjcf_model(arena.mjcf_model)
            physics.forward()
            ids = physics.bind(arena.decoration_geoms).element_id  # (one bind for all: binding is slow)
            for g, geom_id in zip(arena.decoration_geoms, ids):
                c = geom_box_corners(physics, int(geom_id))
                lo, hi = c.min(0), c.max(0)
                for klo, khi in arena.keepout_boxes:
                    inside = np.all(lo < khi - 1e-6) and np.all(klo + 1e-6 < hi)
                    assert not inside, (ROOM_NAMES[room], seed, g.name, lo, hi, klo, khi)


def test_attach_cabinet_at_origin():
    from dm_control import composer

    cab = mjcf.RootElement(model="cabinet")
    cab.worldbody.add("geom", name="carcass", type="box", pos=[0, 0, 0.5], size=[0.3, 0.4, 0.5])
    arena = RoomArena(4, 0)
    arena.attach_cabinet(composer.ModelWrapperEntity(cab))
    physics = mjcf.Physics.from_mjcf_model(arena.mjcf_model)
    physics.forward()
    np.testing.assert_allclose(physics.named.data.geom_xpos["cabinet/carcass"], [0, 0, 0.5], atol=1e-9)
    # The carcass rests on the floor plane: the floor is the only arena geom it can touch.
    assert physics.model.ptr.geom_contype[physics.bind(arena.floor).element_id] == 1
