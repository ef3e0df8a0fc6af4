"""The face on the page: the stream of the render mesh (render.stream) decodes to the positions the
show draws, for a face with a held head and one without; a picture is the show's frame at the
page's aspect; in real headless chromium the page's view of a posed face, as pictures and as the
mesh drawn with WebGL, looks like the show's own offscreen render of it (not like the face at
rest), and a page that hides the face is sent no frames; a page is sent pictures of the size it
shows the face at (smaller when its view shrinks); the pictures use the show's own frame when it
offers one, and a still face makes none."""

from __future__ import annotations

import io

import numpy as np
import pytest
from panel_browser import browser, quit_browser, wait_for

import devices
from devices.events import ControlEvent


def posed(model, steps: int = 40):
    """The default face simulated towards an open jaw, a smile and a glance left."""
    import sim

    from puppet.live import load_face

    state, control = model.rest_state(), sim.FaceControl(model)
    names = [c.name for c in load_face().vocab.channels]
    for ch, v in (("jaw", 0.7), ("zygomaticus_major_l", 0.8), ("zygomaticus_major_r", 0.8), ("eyes_yaw", 0.8)):
        control.values[names.index(ch)] = v
    s = sim.Simulator(model, 1 / 60, wrinkles=False)
    for _ in range(steps):
        s.step(state, control)
    return state


@pytest.mark.parametrize("head", [True, False])
def test_stream_decodes_to_the_drawn_positions(head: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    from puppet.live import load_face
    from render.stream import FRAME, QUANTUM, SCENE, FaceStream, unpack

    if not head:  # a face without the held head (an imported mesh): only its own surface is streamed
        import sim.face.head

        monkeypatch.setattr(sim.face.head, "shell_for", lambda rig: None)
    model = load_face().model
    fs = FaceStream(model)
    kind, h, payload = unpack(fs.scene())
    assert kind == SCENE and h["vertices"] == fs.n_vertices
    n = len(model.rest)
    assert (h["rows"] > n) == head and h["blobs"]["skin_tris"][2] == 3 * len(model.triangles)
    assert (h["blobs"]["head_tris"][2] > 0) == head
    tris = np.frombuffer(payload, np.uint32, h["blobs"]["normal_tris"][2], h["blobs"]["normal_tris"][1])
    assert tris.max() < h["rows"]
    state = posed(model)
    msg = fs.frame(state, 40, 1.5)
    kind, fh, _ = unpack(msg)
    assert kind == FRAME and fh["tick"] == 40 and fh["eye"][0] == pytest.approx(state.eye_yaw)
    want = fs.positions(state)
    assert np.abs(want[:n] - state.surface).max() < 1e-5  # the mask's rows are the drawn surface
    assert np.abs(fs.decode(msg) - want).max() <= QUANTUM / 2 + 1e-5
    # the face at rest is (nearly) all zero steps: its frame is a small fraction of the raw positions
    assert len(fs.frame(model.rest_state(), 0, 0.0)) < fs.n_vertices * 6 / 10


def _canvas_image(drv) -> np.ndarray:
    from PIL import Image
    from selenium.webdriver.common.by import By

    png = drv.find_element(By.ID, "face").screenshot_as_png
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), float)


@pytest.mark.parametrize("mode", ["picture", "mesh"])
def test_page_shows_the_face_the_show_draws(mode: str) -> None:
    from puppet import live
    from puppet.mapping import Mapper
    from puppet.panel.layout import panel_map
    from render.offscreen import OffscreenRenderer

    face = live.load_face()
    dev = devices.open_device(f"panel://127.0.0.1:0?face={mode}", vocab=face.vocab)
    core = live.LiveCore(face, Mapper(panel_map(face.vocab), face.vocab))
    spec = dev.spec.rstrip("/") + "/test"
    moves = [("slider:jaw", 0.7), ("slider:zygomaticus_major_l", 0.8), ("slider:zygomaticus_major_r", 0.8),
             ("slider:eyes_yaw", 0.9)]
    for k in range(60):  # the show's ticks, driven as a page would
        core.tick([ControlEvent(spec, c, "axis", v, None, v, 0.0) for c, v in moves] if k == 0 else [])
    dev.watch(core, [dev])
    watch, hidden = browser(), browser()
    try:
        watch.get(dev.url + "?name=watch")
        hidden.get(dev.url + "?name=hidden&face=0")
        wait_for(lambda: watch.execute_script("const f = window.puppetPanel.face; return f.drawn > 0 && f.tick === 60"),
                 60, "the face drawn on the page")
        assert watch.execute_script("return window.puppetPanel.face.error") is None
        assert watch.execute_script("return window.puppetPanel.face.mode") == mode
        page = _canvas_image(watch)  # as shown: a picture is scaled to the canvas's place on the page
        h, w = page.shape[:2]
        with OffscreenRenderer(face.model, (w, h)) as off:
            show = off.render_frame(core.state).astype(float)
            rest = off.render_frame(face.model.rest_state()).astype(float)
        hh, ww = min(page.shape[0], h), min(page.shape[1], w)
        d_show = np.abs(page[:hh, :ww] - show[:hh, :ww]).mean()
        d_rest = np.abs(page[:hh, :ww] - rest[:hh, :ww]).mean()
        d_pose = np.abs(show - rest).mean()
        assert d_pose > 1.0  # the pose shows
        assert d_show < d_rest / 2, (d_show, d_rest)  # the page shows the posed face, not the rest
        assert d_show < 6.0, d_show  # and close to the show's pixels (antialiasing and 8-bit colour apart)
        assert hidden.execute_script("return window.puppetPanel.face.bytes") == 0
        assert len(dev.face_feed.pages) == 1
        if mode == "picture":  # pictures of the size the page shows the face at; a smaller view, smaller ones
            from render.stream import picture_size

            shown = watch.execute_script("return window.puppetPanel.face.width()")
            assert watch.execute_script("return window.puppetPanel.face.size") == list(picture_size(shown))
            watch.execute_script("document.getElementById('face').style.width = '150px'")
            wait_for(lambda: watch.execute_script("return window.puppetPanel.face.size") == [160, 120], 30,
                     "a smaller picture for a smaller view")
            assert set(dev.face_feed.sizes.values()) == {(160, 120)}
        assert hidden.find_element("id", "facetoggle").get_attribute("aria-pressed") == "false"
        # the show does not move: no picture comes, and the readout says the face is still (not "0 frames/s")
        info = lambda drv: drv.find_element("id", "faceinfo").text  # noqa: E731
        wait_for(lambda: info(watch).startswith("still"), 30, "the readout saying the face is still")
        assert "frames/s" not in info(watch)
        # the readout is redrawn at most 4 times a second: on a loaded machine the hidden page's may lag
        wait_for(lambda: info(hidden) == "not sent to this page", 30, "the hidden page saying no face is sent")
    finally:
        quit_browser(watch)
        quit_browser(hidden)
        dev.close()


def test_a_slow_page_gets_fewer_frames_not_old_ones() -> None:
    """The feed sends a page at most AHEAD frames beyond what it reports drawn; a page that keeps
    up gets every frame of a moving face; both get the scene first."""
    import asyncio

    from puppet.live import load_face
    from puppet.panel.face import AHEAD, FaceFeed
    from render.stream import FRAME, SCENE, unpack

    class Page:
        def __init__(self) -> None:
            self.got: list[bytes] = []

        async def send_bytes(self, data: bytes) -> None:
            self.got.append(data)

    async def run() -> tuple[Page, Page]:
        model = load_face().model
        feed, slow, quick = FaceFeed("mesh"), Page(), Page()
        await feed.add(slow, model)
        await feed.add(quick, model)
        state = model.rest_state()
        for k in range(1, 8):
            state.surface = state.surface + 0.01  # the face moves (a still one is sent nothing new)
            feed.publish(state, k)
            for _ in range(20):  # the sends run to their end
                await asyncio.sleep(0)
            feed.drawn(quick)
        return slow, quick

    slow, quick = asyncio.run(run())
    kinds = lambda page: [unpack(m)[0] for m in page.got]  # noqa: E731
    assert kinds(quick) == [SCENE] + [FRAME] * 7
    assert kinds(slow) == [SCENE] + [FRAME] * AHEAD
    assert [unpack(m)[1]["tick"] for m in slow.got[1:]] == [1, 2]


def test_a_picture_is_the_frame_at_the_pages_aspect() -> None:
    from PIL import Image

    from render.stream import PICTURE, PICTURE_SIZE, picture, unpack

    frame = np.zeros((360, 640, 3), np.uint8)  # a 16:9 frame: the middle 4:3 red, the sides blue
    frame[:, :, 2] = 255
    frame[:, 80:560] = (255, 0, 0)
    kind, h, payload = unpack(picture(frame, "f", 7, 1.25))
    assert kind == PICTURE and h["tick"] == 7 and h["t"] == 1.25 and (h["w"], h["h"]) == PICTURE_SIZE
    img = np.asarray(Image.open(io.BytesIO(payload)).convert("RGB"), float)
    assert img.shape == (PICTURE_SIZE[1], PICTURE_SIZE[0], 3)
    assert np.abs(img[5:-5, 5:-5] - (255, 0, 0)).mean() < 8  # the sides are cropped off


def test_pictures_use_the_shows_own_frame_and_render_without_one() -> None:
    """The show's offered frame is used while fresh, else the state is rendered; a frame or a state
    that shows nothing new (a still face) makes no picture, a moved face does."""
    import asyncio

    from PIL import Image

    from puppet.live import load_face
    from puppet.panel.face import FaceFeed
    from render.stream import unpack

    model = load_face().model
    feed = FaceFeed("picture")

    async def run() -> list[dict | None]:
        shown = np.full((300, 400, 3), (0, 200, 0), np.uint8)  # what the show drew for tick 9
        feed.offer(shown, 9)
        a = await feed.make_picture(model, model.rest_state(), 12)
        again = await feed.make_picture(model, model.rest_state(), 13)  # no newer frame offered
        feed.offer(shown.copy(), 10)  # a newer frame, the same pixels: the face is still
        same = await feed.make_picture(model, model.rest_state(), 14)
        feed.offered = None  # the show stopped offering: the feed renders the state itself
        b = await feed.make_picture(model, model.rest_state(), 14)
        still = await feed.make_picture(model, model.rest_state(), 15)  # later ticks, the same face
        moved = await feed.make_picture(model, posed(model, 10), 16)
        return [a, again, same, b, still, moved]

    try:
        a, again, same, b, still, moved = asyncio.run(run())
    finally:
        feed.close()
    assert a is not None and len(a) == 1
    (a,) = a.values()
    assert unpack(a)[1]["tick"] == 9
    img = np.asarray(Image.open(io.BytesIO(unpack(a)[2])).convert("RGB"), float)
    assert np.abs(img - (0, 200, 0)).mean() < 8
    assert again is None and same is None and still is None
    assert b is not None
    (b,) = b.values()
    assert unpack(b)[1]["tick"] == 14
    rendered = np.asarray(Image.open(io.BytesIO(unpack(b)[2])).convert("RGB"), float)
    assert rendered.std() > 10  # a face, not a flat colour
    assert moved is not None and unpack(next(iter(moved.values())))[1]["tick"] == 16


def test_each_page_gets_the_picture_size_it_asks_for_made_once() -> None:
    """Pages that show the face smaller are sent smaller pictures: each size made once for all its
    pages; a page that was busy when a picture went out gets it once the face is still; a page
    that asks for nothing gets the default size."""
    import asyncio

    from puppet.panel.face import FaceFeed
    from render.stream import PICTURE_SIZE, pictures, unpack

    class Page:
        def __init__(self) -> None:
            self.got: list[bytes] = []

        async def send_bytes(self, data: bytes) -> None:
            self.got.append(data)

    phone, phone2, tablet, quiet = Page(), Page(), Page(), Page()
    feed = FaceFeed("picture")
    frame = np.random.default_rng(1).integers(0, 255, (360, 640, 3), np.uint8)

    async def run() -> None:
        for p in (phone, phone2, tablet, quiet):
            feed.pages[p], feed.ahead[p] = None, 0
        feed.ask(phone, 150)
        feed.ask(phone2, 160)
        feed.ask(tablet, 470)
        assert feed.wanted_sizes() == {(160, 120), (480, 360), PICTURE_SIZE}
        msgs = pictures(frame, "f", 1, 0.0, sorted(feed.wanted_sizes()))
        feed.ahead[quiet] = 2  # two pictures not yet drawn: this one passes it over
        assert feed.send(msgs, 1) == 3
        for _ in range(5):
            await asyncio.sleep(0)
        feed.drawn(quiet)
        assert feed.catch_up() == 1  # nothing new (a still face): the page that missed it gets it
        for _ in range(5):
            await asyncio.sleep(0)
        assert feed.catch_up() == 0  # and nothing more

    asyncio.run(run())
    size = lambda page: [(unpack(m)[1]["w"], unpack(m)[1]["h"]) for m in page.got]  # noqa: E731
    assert size(phone) == size(phone2) == [(160, 120)] and phone.got[0] is phone2.got[0]
    assert size(tablet) == [(480, 360)] and size(quiet) == [PICTURE_SIZE]


def test_the_picture_process_gets_all_the_renderer_reads() -> None:
    """The picture process is sent a state's surface and scalars, not its positions and velocities:
    the picture drawn from that is the picture of the whole state, pixel for pixel."""
    from puppet.live import load_face
    from puppet.panel.pictures import drawn_part
    from render.offscreen import OffscreenRenderer

    model = load_face().model
    state = posed(model, 10)
    state.eye_yaw, state.jaw = 0.6, 0.3
    part = drawn_part(state)
    assert not hasattr(part, "velocities") and part.eye_yaw == 0.6
    with OffscreenRenderer(model, (160, 120)) as off:
        whole = off.render_frame(state)
        assert np.array_equal(off.render_frame(part), whole)
        state.eye_yaw = -0.6  # and what it carries shows: another gaze, another picture
        assert not np.array_equal(off.render_frame(drawn_part(state)), whole)
