"""The web viewer (viser): the face responding live to muscle, action-unit, expression and jaw
controls; views of the skin (plain or textured), muscle vectors, tissue layers and bone nodes;
camera presets; playback of analyses and timelines; exports (contractions, images, video)."""

from __future__ import annotations

import json
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from myoface.control import au_table, list_expressions
from myoface.errors import MyofaceDependencyError, MyofaceError, MyofaceValueError
from myoface.render import Camera, Renderer, VideoWriter
from myoface.render.renderer import to_srgb8
from myoface.synth import Synthesizer
from myoface.viewer.scene import MM, FaceScene
from myoface.viewer.state import REGIONS, PhysicsWorker, ViewerState, region_of

UI_AUS = (1, 2, 4, 5, 6, 7, 9, 10, 12, 14, 15, 16, 17, 20, 23, 24, 25, 26, 27)
#: camera presets: name -> (Camera preset, side)
CAMERA_PRESETS = {
    "front": ("front", None),
    "3/4 left": ("three_quarter", "l"),
    "3/4 right": ("three_quarter", "r"),
    "profile left": ("profile", "l"),
    "profile right": ("profile", "r"),
}
#: exported images and videos: height in pixels (width follows the browser's aspect)
EXPORT_HEIGHT = 720
VIDEO_HEIGHT = 360
VIDEO_FPS = 30.0
MAX_EXPORT_WIDTH = 1920
#: the skin's opacity when a view of the tissue under it is switched on
SEE_THROUGH_OPACITY = 0.35


def _viser():
    try:
        import viser
    except ImportError:
        raise MyofaceDependencyError(
            'the viewer needs viser: pip install "myoface[viewer]"'
        ) from None
    return viser


def check_address(host: str, port: int) -> str:
    """Check that a server can listen on ``host``:``port`` before starting it; returns the
    address ``host`` resolves to.

    A clear :class:`~myoface.errors.MyofaceValueError` for a port outside 0-65535 (0: any free
    port), a host name that does not resolve, an address that is not this machine's, and a port
    that another program is listening on (the server would otherwise move to another port or,
    for a host it cannot listen on, wait forever).
    """
    import errno
    import socket

    if isinstance(port, bool) or not isinstance(port, int | np.integer) or not 0 <= port <= 65535:
        raise MyofaceValueError(
            f"port must be an integer in [0, 65535] (0: any free); got {port!r}"
        )
    if not isinstance(host, str) or not host.strip():
        raise MyofaceValueError(f"host must be a host name or an address; got {host!r}")
    try:
        infos = socket.getaddrinfo(
            host, int(port), type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )
    except (socket.gaierror, UnicodeError, OSError) as exc:
        msg = getattr(exc, "strerror", None) or str(exc)
        raise MyofaceValueError(f"host {host!r} does not resolve to an address: {msg}") from None
    family, kind, proto, _, addr = infos[0]
    with socket.socket(family, kind, proto) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server will
        try:
            sock.bind(addr)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise MyofaceValueError(
                    f"port {port} on {host} is in use by another program; choose another port "
                    "(0: any free one)"
                ) from None
            if exc.errno == errno.EADDRNOTAVAIL:
                shown = host if addr[0] == host else f"{host} ({addr[0]})"
                raise MyofaceValueError(f"host {shown} is not an address of this machine") from None
            if exc.errno == errno.EACCES:
                raise MyofaceValueError(
                    f"no permission to listen on port {port} (ports below 1024 need privileges)"
                ) from None
            raise MyofaceValueError(f"cannot listen on {host}:{port}: {exc.strerror}") from None
    return str(addr[0])


def _aspect(camera) -> float:
    """A browser camera's width / height (1 before the browser said)."""
    return float(getattr(camera, "aspect", 1.0) or 1.0)


def _png(image: np.ndarray) -> bytes:
    import imageio.v3 as iio

    return iio.imwrite("<bytes>", np.asarray(image, dtype=np.uint8), extension=".png")


class FaceViewer:
    """A running viewer: ``FaceViewer(model, port=8080).serve_forever()``; ``url`` says where.

    Parameters
    ----------
    model : FaceModel
    host, port : where to serve (``port=0``: any free port).
    texture : image array or path for the face's UVs (default: the face's own texture, else the
        default face's neutral skin texture).
    """

    def __init__(self, model, host: str = "127.0.0.1", port: int = 8080, texture=None):
        viser = _viser()
        check_address(host, port)
        self.model = model
        self.state = ViewerState(model)
        self.renderer = Renderer(model.face, Camera.front(model.face.vertices), texture=texture)
        tex = self.renderer.texture
        self._texture8 = None if tex is None else to_srgb8(tex)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.host, self.port = host, self.server.get_port()
        if port and self.port != port:  # taken since check_address: viser moved on
            self.server.stop()
            raise MyofaceValueError(f"port {port} on {host} is in use by another program")
        self.scene = FaceScene(self.server.scene, model, self.renderer)
        self.worker = PhysicsWorker(model, self._publish, self._notify)
        self.worker.start()
        self._syncing = False
        self._sliders = {}
        self._playing = False
        self._exporting = False
        self._closed = threading.Event()
        self.last_error = ""
        self.last_message = ""
        self.last_download: tuple[str, bytes] | None = None
        self._build_gui()
        self.server.on_client_connect(self._on_connect)

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    # ------------------------------------------------------------------ plumbing
    def _publish(self, x: np.ndarray) -> None:
        self.scene.update(x, jaw=self.model.jaw_pose(self.worker.current))

    def _notify(self, message: str, error: bool = True) -> None:
        if error:
            self.last_error = message
        else:
            self.last_message = message
        for client in self.server.get_clients().values():
            try:
                client.add_notification(
                    title="myoface", body=message, color="red" if error else "green"
                )
            except Exception:  # noqa: BLE001 - a client that went away must not stop us
                pass

    def _on_connect(self, client) -> None:
        self.set_camera(client, "front")

    def _update(self) -> None:
        self.worker.request(self.state.contractions())

    def _guard(self, fn):
        """Run a control callback; errors become a notification, the server keeps running."""

        def wrapped(event=None):
            try:
                fn(event)
            except MyofaceError as exc:
                self._notify(str(exc))

        return wrapped

    # ------------------------------------------------------------------ cameras
    def camera_preset(self, name: str, width: int, height: int, fov_deg: float) -> Camera:
        """The preset camera ``name`` (see :data:`CAMERA_PRESETS`) framing the face."""
        if name not in CAMERA_PRESETS:
            raise MyofaceValueError(f"unknown camera preset {name!r}")
        kind, side = CAMERA_PRESETS[name]
        kw = {"width": int(width), "height": int(height), "fov_deg": float(fov_deg)}
        if side is not None:
            kw["side"] = side
        return getattr(Camera, kind)(self.model.face.vertices, **kw)

    def set_camera(self, client, name: str) -> None:
        """Move a browser's camera to a preset."""
        cam = client.camera
        preset = self.camera_preset(name, round(400 * _aspect(cam)), 400, np.rad2deg(cam.fov))
        with client.atomic():
            cam.up_direction = tuple(preset.up)
            cam.position = tuple(preset.eye * MM)
            cam.look_at = tuple(preset.target * MM)

    def client_camera(self, client, height: int) -> Camera:
        """A renderer camera that sees what ``client``'s browser sees, ``height`` px high (the
        width is even, as video encoders want)."""
        cam = client.camera
        width = 2 * int(min(MAX_EXPORT_WIDTH, max(16, height * _aspect(cam))) // 2)
        return Camera(
            np.asarray(cam.position, float) / MM,
            np.asarray(cam.look_at, float) / MM,
            np.asarray(cam.up_direction, float),
            width,
            int(height),
            float(np.rad2deg(cam.fov)),
        )

    # ------------------------------------------------------------------ exports
    def render_image(self, camera: Camera | None = None) -> np.ndarray:
        """The current face rendered on the CPU (textured, lit, dressed) as uint8 RGB."""
        camera = camera or self.renderer.camera
        r = Renderer(self.model.face, camera, texture=self._texture8)
        st = self.worker.current
        return r.render(self.model.skin_vertices(st), jaw=self.model.jaw_pose(st))

    def playback_video(
        self, path, camera: Camera | None = None, fps: float = VIDEO_FPS, on_frame=None
    ) -> Path:
        """Render the loaded playback to a video file at ``fps`` with a state of its own (the
        live face is not disturbed); ``on_frame(k, n)`` reports progress."""
        if self.state.playback is None:
            raise MyofaceValueError("load a contractions.csv or a timeline first")

        times, _ = self.state.playback
        n = max(1, int(np.floor((times[-1] - times[0]) * fps)) + 1)
        camera = camera or Camera.front(
            self.model.face.vertices, width=VIDEO_HEIGHT, height=VIDEO_HEIGHT
        )
        syn = Synthesizer(self.model, Renderer(self.model.face, camera, texture=self._texture8))
        with VideoWriter(path, fps) as vw:
            for k in range(n):
                t = times[0] + k / fps
                syn.gaze = self.state.gaze_at(t)  # (the playback's eyes, if it has them)
                vw.write(syn.image(self.state.frame_at(t)))
                if on_frame is not None:
                    on_frame(k + 1, n)
        return Path(path)

    def _download(self, event, filename: str, data: bytes) -> None:
        client = getattr(event, "client", None) if event is not None else None
        if client is None:
            return
        try:
            client.send_file_download(filename, data, save_immediately=True)
            self.last_download = (filename, data)
        except Exception as exc:  # noqa: BLE001 - the client may have gone
            self._notify(f"could not send {filename}: {exc}")

    def _export_contractions(self, event) -> None:
        data = json.dumps(
            dict(zip(self.model.ids, self.state.contractions().tolist(), strict=True)), indent=1
        ).encode()
        self._download(event, "contractions.json", data)

    def _export_screenshot(self, event) -> None:
        client = event.client
        cam = self.client_camera(client, EXPORT_HEIGHT)
        img = np.asarray(
            client.get_render(cam.height, cam.width, transport_format="png", timeout=20.0)
        )
        if img.shape[-1] == 4:  # the page's background is transparent: put it on white
            a = img[..., 3:4].astype(np.float64) / 255.0
            img = np.round(img[..., :3] * a + 255.0 * (1.0 - a)).astype(np.uint8)
        self._download(event, "myoface_view.png", _png(img))

    def _export_render(self, event) -> None:
        img = self.render_image(self.client_camera(event.client, EXPORT_HEIGHT))
        self._download(event, "myoface_render.png", _png(img))

    def _export_video(self, event) -> None:
        if self.state.playback is None:
            raise MyofaceValueError("load a contractions.csv or a timeline first")
        if self._exporting:
            raise MyofaceValueError("a video export is already running")
        cam = self.client_camera(event.client, VIDEO_HEIGHT)

        def work():
            self._exporting = True
            try:
                with tempfile.TemporaryDirectory() as tmp:
                    path = Path(tmp) / "myoface_playback.mp4"

                    def report(k, n):
                        self._status.content = f"rendering video: frame {k} of {n}"

                    self.playback_video(path, cam, on_frame=report)
                    self._status.content = "video ready"
                    self._download(event, path.name, path.read_bytes())
            except MyofaceError as exc:
                self._notify(str(exc))
            except Exception as exc:  # noqa: BLE001 - reported; the server keeps running
                self._notify(f"video export failed: {exc}")
            finally:
                self._exporting = False

        threading.Thread(target=work, daemon=True).start()

    def gltf_export(self, path) -> Path:
        """The loaded playback (its file, as ``myoface export FILE`` exports it: a CSV's head
        pose and gaze included), or without one the face as it is now (one frame), as a binary
        glTF at ``path`` (:func:`myoface.export.export_glb`); returns the path."""
        from myoface.export import Clip, clip_from_csv, clip_from_timeline, export_glb

        src = self.state.playback_path if self.state.playback is not None else None
        if src is None:
            clip = Clip(self.state.contractions()[None], VIDEO_FPS, source="viewer")
        elif src.suffix.lower() == ".csv":
            clip = clip_from_csv(src, self.model)
        else:
            from myoface.control import load_timeline

            clip = clip_from_timeline(load_timeline(src), self.model, VIDEO_FPS)
        return export_glb(self.model, clip, path).path

    def _export_gltf(self, event) -> None:
        if self._exporting:
            raise MyofaceValueError("an export is already running")

        def work():
            self._exporting = True
            try:
                with tempfile.TemporaryDirectory() as tmp:
                    self._status.content = "exporting glTF ..."
                    path = self.gltf_export(Path(tmp) / "myoface_animation.glb")
                    self._status.content = "glTF ready"
                    self._download(event, path.name, path.read_bytes())
            except MyofaceError as exc:
                self._notify(str(exc))
            except Exception as exc:  # noqa: BLE001 - reported; the server keeps running
                self._notify(f"glTF export failed: {exc}")
            finally:
                self._exporting = False

        threading.Thread(target=work, daemon=True).start()

    # ------------------------------------------------------------------ GUI
    def _build_gui(self) -> None:
        gui = self.server.gui
        ids = self.model.ids
        link = gui.add_checkbox("link left and right", initial_value=True)

        @link.on_update
        def _(event) -> None:
            self.state.linked = link.value

        order = ["mouth corners", *[r for r in REGIONS if r != "mouth corners"], "other"]
        for region in order:
            members = [m for m in ids if m != "jaw" and region_of(m) == region]
            if not members:
                continue
            with gui.add_folder(region, expand_by_default=region == "mouth corners"):
                for mid in members:
                    self._sliders[mid] = self._muscle_slider(gui, mid)
        if "jaw" in ids:
            self._sliders["jaw"] = self._muscle_slider(gui, "jaw")
        reset = gui.add_button("reset")
        reset.on_click(self._guard(lambda e: self._reset()))
        self._expression_gui(gui)
        self._au_gui(gui)
        self._preset_gui(gui)
        self._view_gui(gui)
        self._playback_gui(gui)
        with gui.add_folder("export", expand_by_default=False):
            b = gui.add_button("contractions (JSON)")
            b.on_click(self._guard(self._export_contractions))
            b = gui.add_button("screenshot of this view (PNG)")
            b.on_click(self._guard(self._export_screenshot))
            b = gui.add_button("render this view on the CPU (PNG)")
            b.on_click(self._guard(self._export_render))
            b = gui.add_button("animation of the playback, or this face (glTF .glb)")
            b.on_click(self._guard(self._export_gltf))

    def _expression_gui(self, gui) -> None:
        with gui.add_folder("expression", expand_by_default=False):
            expr = gui.add_dropdown(
                "expression", ("none", *list_expressions()), initial_value="none"
            )
            inten = gui.add_slider("intensity", min=0.0, max=1.0, step=0.01, initial_value=1.0)

            def set_expr(_event=None):
                self.state.set_expression(expr.value, inten.value)
                self._update()

            expr.on_update(self._guard(set_expr))
            inten.on_update(self._guard(set_expr))

    def _au_gui(self, gui) -> None:
        table = au_table()
        with gui.add_folder("action units", expand_by_default=False):
            for n in UI_AUS:
                if n not in table:
                    continue
                s = gui.add_slider(
                    f"AU{n} {table[n].name}", min=0.0, max=1.0, step=0.01, initial_value=0.0
                )

                def set_au(event, n=n, s=s):
                    self.state.set_au(n, s.value)
                    self._update()

                s.on_update(self._guard(set_au))

    def _preset_gui(self, gui) -> None:
        with gui.add_folder("presets", expand_by_default=False):
            self._preset_menu = gui.add_dropdown(
                "preset", tuple(self.state.presets), initial_value="neutral"
            )
            apply = gui.add_button("apply preset")
            name = gui.add_text("name", initial_value="")
            save = gui.add_button("save current as preset")
            path = gui.add_text("preset file (JSON)", initial_value="")
            load = gui.add_button("load preset file")

            def do_apply(event):
                self.apply_preset(self._preset_menu.value)

            def do_save(event):
                self.state.save_preset(name.value)
                self._refresh_presets(name.value.strip())

            def do_load(event):
                stem = self.state.load_preset_file(path.value)
                self._refresh_presets(stem)
                self._sync_sliders()
                self._update()

            apply.on_click(self._guard(do_apply))
            save.on_click(self._guard(do_save))
            load.on_click(self._guard(do_load))

    def _refresh_presets(self, current: str) -> None:
        self._preset_menu.options = tuple(self.state.presets)
        self._preset_menu.value = current

    def _view_gui(self, gui) -> None:
        sc = self.scene
        with gui.add_folder("view", expand_by_default=False):
            for name in CAMERA_PRESETS:
                b = gui.add_button(f"camera: {name}")

                def on_cam(event, name=name):
                    if event.client is not None:
                        self.set_camera(event.client, name)

                b.on_click(self._guard(on_cam))
            if sc.textured is not None:
                tex = gui.add_checkbox("textured skin", initial_value=False)
                tex.on_update(self._guard(lambda e: sc.set_textured(tex.value)))
            show = gui.add_checkbox("muscle vectors", initial_value=False)

            @show.on_update
            def _(event) -> None:
                sc.vectors.visible = show.value

            skin = gui.add_slider("skin opacity", min=0.1, max=1.0, step=0.05, initial_value=1.0)

            def on_opacity(event=None):
                sc.skin.opacity = None if skin.value >= 1.0 else float(skin.value)

            skin.on_update(self._guard(on_opacity))

            def see_inside(on: bool) -> None:
                # what lies under the skin shows through it: make an opaque skin translucent
                if on and skin.value >= 1.0:
                    skin.value = SEE_THROUGH_OPACITY
                    on_opacity()

            for layer in sc.layers:
                box = gui.add_checkbox(f"lattice: {layer} springs", initial_value=False)

                def on_layer(event, layer=layer, box=box):
                    with self.worker.lock:
                        sc.set_layer(layer, box.value)
                    see_inside(box.value)

                box.on_update(self._guard(on_layer))
            bones = gui.add_checkbox("bone nodes", initial_value=False)

            def on_bones(event):
                with self.worker.lock:
                    sc.set_bones(bones.value)
                see_inside(bones.value)

            bones.on_update(self._guard(on_bones))

    def _playback_gui(self, gui) -> None:
        with gui.add_folder("playback", expand_by_default=False):
            path = gui.add_text("file (contractions.csv or timeline)", initial_value="")
            load = gui.add_button("load")
            play = gui.add_button("play")
            self._time = gui.add_slider("time (s)", min=0.0, max=1.0, step=0.01, initial_value=0.0)
            video = gui.add_button("export video of the playback (MP4)")
            self._status = gui.add_markdown("")

            def do_load(event):
                dur = self.state.load_playback(path.value.strip())
                self._time.max = max(dur, 0.01)
                self._time.value = 0.0

            load.on_click(self._guard(do_load))
            play.on_click(self._guard(lambda e: self._play()))
            self._time.on_update(self._guard(lambda e: self._scrub()))
            video.on_click(self._guard(self._export_video))

    def _muscle_slider(self, gui, mid: str):
        s = gui.add_slider(mid.replace("_", " "), min=0.0, max=1.0, step=0.01, initial_value=0.0)

        def on_change(event, mid=mid, s=s):
            if self._syncing:
                return
            self.state.set_muscle(mid, s.value)
            if self.state.linked and mid.endswith(("_l", "_r")):
                twin = mid[:-1] + ("r" if mid.endswith("l") else "l")
                if twin in self._sliders:
                    self._syncing = True
                    try:
                        self._sliders[twin].value = s.value
                    finally:
                        self._syncing = False
            self._update()

        s.on_update(self._guard(on_change))
        return s

    def _sync_sliders(self) -> None:
        """Show the state's muscle values on the sliders without triggering their callbacks."""
        self._syncing = True
        try:
            for mid, s in self._sliders.items():
                s.value = float(round(self.state.muscles[self.model.ids.index(mid)], 2))
        finally:
            self._syncing = False

    def apply_preset(self, name: str) -> None:
        """Set the face to a preset (see :meth:`ViewerState.apply_preset`) and the sliders with
        it."""
        self.state.apply_preset(name)
        self._sync_sliders()
        self._update()

    def _reset(self) -> None:
        self.state.reset()
        self._sync_sliders()
        self._update()

    def _scrub(self) -> None:
        if self.state.playback is not None:
            self.scene.set_gaze(self.state.gaze_at(self._time.value))
            self.worker.request(self.state.frame_at(self._time.value))

    def _play(self) -> None:
        if self.state.playback is None:
            raise MyofaceError("load a contractions.csv or a timeline first")
        if self._playing:
            return
        # (playing from the click on: a second click before the loop's thread runs starts
        # no second loop)
        self._playing = True

        def loop():
            try:
                t0 = time.perf_counter()
                dur = self._time.max
                while not self._closed.is_set():
                    t = time.perf_counter() - t0
                    if t > dur:
                        break
                    self._time.value = round(t, 2)
                    self._closed.wait(1 / 30)
            except Exception as exc:  # noqa: BLE001 - reported; the server keeps running
                self._notify(f"playback stopped: {exc}")
            finally:
                self._playing = False

        try:
            threading.Thread(target=loop, daemon=True).start()
        except BaseException:
            self._playing = False
            raise

    # ------------------------------------------------------------------ lifetime
    def apply(self, contractions, timeout_s: float = 10.0) -> np.ndarray:
        """Relax to ``contractions`` now (as a slider would) and wait until it settled."""
        self.worker.request(self.model.validate(contractions))
        time.sleep(0.001)
        self.worker.settled.wait(timeout_s)
        return self.model.skin_vertices(self.worker.current)

    def serve_forever(self) -> None:
        try:
            while True:
                time.sleep(1.0)
        finally:
            self.close()

    def close(self) -> None:
        self._closed.set()
        self.worker.stop()
        self.server.stop()
