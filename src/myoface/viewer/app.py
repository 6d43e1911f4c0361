"""The web viewer (viser): the face responding live to muscle, action-unit, expression and jaw
controls, with muscle vectors, playback of analyses and timelines, and exports."""

from __future__ import annotations

import json
import threading
import time

import numpy as np

from myoface.errors import MyofaceDependencyError, MyofaceError
from myoface.viewer.state import REGIONS, PhysicsWorker, ViewerState, region_of

SKIN_RGB = (226, 178, 154)
UI_AUS = (1, 2, 4, 5, 6, 7, 9, 10, 12, 14, 15, 16, 17, 20, 23, 24, 25, 26, 27)
MM = 1e-3  # the scene is in metres


def _viser():
    try:
        import viser
    except ImportError:
        raise MyofaceDependencyError(
            'the viewer needs viser: pip install "myoface[viewer]"'
        ) from None
    return viser


class FaceViewer:
    """A running viewer: ``FaceViewer(model, port=8080).serve_forever()``; ``url`` says where."""

    def __init__(self, model, host: str = "127.0.0.1", port: int = 8080):
        viser = _viser()
        self.model = model
        self.state = ViewerState(model)
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.host, self.port = host, self.server.get_port()
        v = model.skin_vertices()
        self.mesh = self.server.scene.add_mesh_simple(
            "/face",
            (v * MM).astype(np.float32),
            model.face.triangles.astype(np.int32),
            color=SKIN_RGB,
            side="double",
        )
        ins = np.array([m.insertion for m in model.muscles.muscles])
        org = np.array([m.origin for m in model.muscles.muscles])
        self.vectors = self.server.scene.add_line_segments(
            "/muscles",
            (np.stack([ins, org], axis=1) * MM).astype(np.float32),
            colors=(255, 200, 40),
            thickness=2.0,
            thickness_units="screen",
            visible=False,
        )
        self.worker = PhysicsWorker(model, self._publish, self._notify)
        self.worker.start()
        self._syncing = False
        self._sliders = {}
        self._playing = False
        self._build_gui()
        self.server.on_client_connect(self._on_connect)
        self.last_error = ""

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    # ------------------------------------------------------------------ plumbing
    def _publish(self, skin: np.ndarray) -> None:
        self.mesh.vertices = (skin * MM).astype(np.float32)

    def _notify(self, message: str) -> None:
        self.last_error = message
        for client in self.server.get_clients().values():
            try:
                client.add_notification(title="myoface", body=message, color="red")
            except Exception:  # noqa: BLE001 - a client that went away must not stop us
                pass

    def _on_connect(self, client) -> None:
        client.camera.position = (0.0, 0.0, 0.42)
        client.camera.look_at = (0.0, -0.005, 0.04)
        client.camera.up_direction = (0.0, 1.0, 0.0)

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
        with gui.add_folder("expression", expand_by_default=False):
            from myoface.control import list_expressions

            expr = gui.add_dropdown(
                "expression", ("none", *list_expressions()), initial_value="none"
            )
            inten = gui.add_slider("intensity", min=0.0, max=1.0, step=0.01, initial_value=1.0)

            def set_expr(_event=None):
                self.state.set_expression(expr.value, inten.value)
                self._update()

            expr.on_update(self._guard(set_expr))
            inten.on_update(self._guard(set_expr))
        with gui.add_folder("action units", expand_by_default=False):
            from myoface.control import au_table

            table = au_table()
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
        with gui.add_folder("view", expand_by_default=False):
            show = gui.add_checkbox("muscle vectors", initial_value=False)

            @show.on_update
            def _(event) -> None:
                self.vectors.visible = show.value

            reset = gui.add_button("reset")
            reset.on_click(self._guard(lambda e: self._reset()))
            export = gui.add_button("download contractions (JSON)")
            export.on_click(self._guard(self._export))
        with gui.add_folder("playback", expand_by_default=False):
            path = gui.add_text("file (contractions.csv or timeline)", initial_value="")
            load = gui.add_button("load")
            play = gui.add_button("play")
            self._time = gui.add_slider("time (s)", min=0.0, max=1.0, step=0.01, initial_value=0.0)

            def do_load(event):
                dur = self.state.load_playback(path.value.strip())
                self._time.max = max(dur, 0.01)
                self._time.value = 0.0

            load.on_click(self._guard(do_load))
            play.on_click(self._guard(lambda e: self._play()))
            self._time.on_update(self._guard(lambda e: self._scrub()))

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

    def _reset(self) -> None:
        self.state.reset()
        self._syncing = True
        try:
            for s in self._sliders.values():
                s.value = 0.0
        finally:
            self._syncing = False
        self._update()

    def _export(self, event) -> None:
        data = json.dumps(
            dict(zip(self.model.ids, self.state.contractions().tolist(), strict=True)), indent=1
        ).encode()
        if event is not None and getattr(event, "client", None) is not None:
            event.client.send_file_download("contractions.json", data)

    def _scrub(self) -> None:
        if self.state.playback is not None:
            self.worker.request(self.state.frame_at(self._time.value))

    def _play(self) -> None:
        if self.state.playback is None:
            raise MyofaceError("load a contractions.csv or a timeline first")
        if self._playing:
            return

        def loop():
            self._playing = True
            try:
                t0 = time.perf_counter()
                dur = self._time.max
                while True:
                    t = time.perf_counter() - t0
                    if t > dur:
                        break
                    self._time.value = round(t, 2)
                    time.sleep(1 / 30)
            finally:
                self._playing = False

        threading.Thread(target=loop, daemon=True).start()

    # ------------------------------------------------------------------ lifetime
    def apply(self, contractions, timeout_s: float = 10.0) -> np.ndarray:
        """Relax to ``contractions`` now (as a slider would) and wait until it settled."""
        self.worker.request(self.model.validate(contractions))
        time.sleep(0.001)
        self.worker.settled.wait(timeout_s)
        return self.model.skin_vertices()

    def serve_forever(self) -> None:
        try:
            while True:
                time.sleep(1.0)
        finally:
            self.close()

    def close(self) -> None:
        self.worker.stop()
        self.server.stop()
