"""mavstack.aio's gimbals and cameras: the simulated vehicle's gimbal and its camera
(`mavstack vehicle --camera DIR`: each photo an image file in DIR), and a camera served
from Python (`mavstack.aio.serve_camera`) found, asked for a photo and set by a ground
station, with pymavlink watching the same link for the announcement the camera sends."""

import asyncio
import os
import tempfile

import pytest

import mavstack.aio as aio
from conftest import Vehicle, free_port


def run(coro, timeout=90):
    return asyncio.run(asyncio.wait_for(coro, timeout))


def test_the_simulated_gimbal_and_camera():
    port = free_port()
    photos = tempfile.mkdtemp(prefix="mavstack-photos-")

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)

            gimbals = await vehicle.gimbals()
            assert len(gimbals) == 1
            g = gimbals[0]
            assert (g.info.manager_system, g.info.manager_component, g.info.device_id) == (1, 1, 1)
            assert g.info.pitch_limits == (-90.0, 30.0)
            await g.take_control()
            control = await g.control()
            assert control.primary == (255, 190), control
            await g.set_angles(-30, 45)
            for _ in range(100):
                a = await g.attitude()
                if abs(a.pitch_deg + 30) < 1 and abs(a.yaw_deg - 45) < 1:
                    break
                await asyncio.sleep(0.1)
            assert a.frame == "vehicle" and abs(a.pitch_deg + 30) < 1 and abs(a.yaw_deg - 45) < 1, a
            # Beyond the manager's limits, NaN: refused before anything is sent.
            with pytest.raises(aio.InvalidValueError, match="outside the gimbal's limits"):
                await g.set_angles(60, 0)
            with pytest.raises(aio.InvalidValueError):
                await g.set_angles(float("nan"), 0)
            await g.point_at(-35.3623, 149.1652, 584)
            await g.clear_roi()
            await g.release_control()

            cameras = await vehicle.cameras()
            assert len(cameras) == 1
            cam = cameras[0]
            assert (cam.info.system, cam.info.component) == (1, 100)
            assert cam.info.definition_uri == "mftp://camera.xml"
            photo = await cam.take_photo()
            assert photo.success and photo.index == 0
            path = os.path.join(photos, "IMG_0000.pgm")
            assert photo.file_url == "file://" + path
            assert os.path.getsize(path) > 320 * 240
            assert (await cam.capture_status()).image_count == 1
            storage = await cam.storage()
            assert storage and storage[0].total_mib > 0
            settings = {s.name: s for s in await cam.settings()}
            assert settings["CAM_ISO"].excluded, settings["CAM_ISO"]
            with pytest.raises(aio.InvalidValueError, match="CAM_ISO does not apply"):
                await cam.set("CAM_ISO", 400)
            await cam.set("CAM_EXPMODE", "manual")
            assert await cam.set("CAM_ISO", 400) == 400
            await cam.start_video()
            assert (await cam.capture_status()).video_on
            await cam.stop_video()

    with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", "px4", "--camera", photos):
        run(session())


def test_a_camera_served_from_python():
    port = free_port()

    async def camera_side(ready: asyncio.Event, taken: list):
        async with aio.serve_camera("udpout:127.0.0.1:%d" % port, system=1, component=100,
                                    model="Python camera",
                                    definition=aio.SIMULATED_CAMERA_DEFINITION) as server:
            ready.set()
            async for request in server:
                taken.append(request)
                if request.kind == "photo":
                    server.photo_taken(request.number, "file:///photos/%d.jpg" % request.number,
                                       2.5)
                if request.kind == "video_stop":
                    return await server.settings()

    async def gcs_side(ready: asyncio.Event):
        await ready.wait()
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            # A camera and no autopilot: reached as system 1's component 100.
            vehicle = await gcs.vehicle(timeout=10, system=1, component=100)
            cameras = await vehicle.cameras()
            assert [c.info.model for c in cameras] == ["Python camera"]
            cam = cameras[0]
            photo = await cam.take_photo()
            assert photo.success and photo.file_url == "file:///photos/0.jpg", photo
            photo = await cam.take_photo()
            assert photo.index == 1
            await cam.set("CAM_WBMODE", 2)
            await cam.start_video()
            await cam.stop_video()

    async def both():
        ready = asyncio.Event()
        taken: list = []
        cam = asyncio.create_task(camera_side(ready, taken))
        await gcs_side(ready)
        settings = await asyncio.wait_for(cam, 30)
        kinds = [r.kind for r in taken]
        assert kinds[:2] == ["photo", "photo"], kinds
        assert "setting" in kinds and kinds[-2:] == ["video_start", "video_stop"], kinds
        assert settings["CAM_WBMODE"] == 2, settings

    run(both())
