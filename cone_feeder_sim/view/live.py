# Copyright 2026 The cone_feeder_sim Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The live view: a Foxglove WebSocket server that shows a run as it goes, without ROS.

:class:`LiveView` serves the topics of :data:`~cone_feeder_sim.view.topics.VIEW_TOPICS` with
foxglove-sdk (the optional extra ``[view]``). The simulation hands it snapshots (as the
runner's progress callback, after the engine's ticks, or with :meth:`LiveView.show`); its
own thread publishes the newest one at a steady frame rate (``fps``, wall clock), whatever
the tick rate, with the exits and packs since the last frame as log lines. The simulation
only hands over its state; it never waits for a client, and a client that connects late,
or vanishes, changes nothing in the run. A new subscription gets the last frame again at
the next frame time, so that a client that connects after the run's end sees its end.
Open it in Foxglove with "Open connection", ``ws://HOST:PORT`` (config/foxglove_layout.json
arranges the panels).
"""

from collections.abc import Sequence
import importlib
import json
import threading
import time
from types import ModuleType, TracebackType
from typing import Any, Self, TYPE_CHECKING

from .snapshot import Event, Moment, Snapshot, Watcher
from .topics import JSON_SCHEMAS, VIEW_TOPICS
from ..errors import ViewError
from ..feeder.engine import FeederEngine, TickResult
from ..formats.messages import stamp_ns
from ..physics.params import ModelParams
from ..physics.simulation import Simulator, StepResult
from ..weigher.machine import Weigher

if TYPE_CHECKING:
    import foxglove.websocket

__all__ = ['DEFAULT_FPS', 'DEFAULT_PORT', 'INSTALL_HINT', 'LiveView', 'MAX_FPS', 'require_sdk']

#: Foxglove's default WebSocket port.
DEFAULT_PORT = 8765
#: Frames per second (wall clock) the view publishes by default, and at most.
DEFAULT_FPS = 30.0
MAX_FPS = 120.0
#: How to install what the live view needs.
INSTALL_HINT = ('the live view needs foxglove-sdk: pip install "foxglove-sdk>=0.30" (the '
                '[view] extra of cone_feeder_sim)')


def require_sdk() -> ModuleType:
    """Return the foxglove module; raise ViewError with the install hint without it."""
    try:
        return importlib.import_module('foxglove')
    except ImportError:
        raise ViewError(INSTALL_HINT) from None


class LiveView:
    """
    A Foxglove WebSocket server showing one run live.

    source: the engine to watch (its model and weigher; every tick of it is shown) or the
    run's model. weigher: the machine the headless runner drives (its hopper readings and
    packs; ignored with an engine). port: the TCP port (0: any free one, see
    :attr:`port`); host: the address to bind (default this machine only). fps: frames per
    wall second, at most MAX_FPS. Raises ViewError when foxglove-sdk is missing or the port
    cannot be bound; nothing is served then.

    Use it as a context manager or call :meth:`close`. A watched engine feeds it by itself;
    else feed it with :meth:`__call__` (the runner's progress callback), :meth:`ticked`
    (after an engine's ticks) or :meth:`show`.
    Counters for benchmarks: ``frames`` published, ``publish_seconds`` spent publishing
    (wall, on the view's thread).
    """

    def __init__(self, source: FeederEngine | ModelParams, *, weigher: Weigher | None = None,
                 port: int = DEFAULT_PORT, host: str = '127.0.0.1',
                 fps: float = DEFAULT_FPS, name: str = 'cone_feeder_sim') -> None:
        """Start the server and the frame thread."""
        if not 0.0 < fps <= MAX_FPS:
            raise ViewError(f'the live view needs 0 < fps <= {MAX_FPS:g}, got {fps}')
        sdk = require_sdk()
        from . import scene  # needs foxglove-sdk
        self._lock = threading.Lock()
        self._latest: Snapshot | Moment | None = None
        self._events: list[Event] = []
        self._engine: FeederEngine | None = None
        self.watch(source, weigher)
        self._resend = threading.Event()  # a client subscribed: send the last frame again
        self._messages = scene
        self._scene = scene.SceneBuilder(self._model)
        self._context = sdk.Context()
        try:
            self._server = sdk.start_server(
                name=name, host=host, port=port, context=self._context,
                capabilities=[sdk.Capability.Time],
                server_listener=_listener(sdk, self._resend))
        except RuntimeError as exc:
            raise ViewError(f'cannot serve the live view on {host}:{port}: {exc}') from None
        try:
            self._channels: dict[str, Any] = {
                'scene': sdk.channels.SceneUpdateChannel(VIEW_TOPICS['scene'].name,
                                                         context=self._context),
                'events': sdk.channels.LogChannel(VIEW_TOPICS['events'].name,
                                                  context=self._context)}
            for key, schema in JSON_SCHEMAS.items():
                self._channels[key] = sdk.Channel(VIEW_TOPICS[key].name, schema=schema,
                                                  message_encoding='json',
                                                  context=self._context)
        except BaseException:
            self._server.stop()
            raise
        self.host = host
        self._port = int(self._server.port)
        self.period = 1.0 / fps
        self.frames = 0
        self.publish_seconds = 0.0
        #: The error that stopped the frame thread (the run goes on; the view freezes).
        self.error: BaseException | None = None
        self._sent: Snapshot | Moment | None = None
        self._shown: Snapshot | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='live-view', daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        """Return the TCP port the server listens on."""
        return self._port

    @property
    def url(self) -> str:
        """Return the address to open in Foxglove (Open connection, Foxglove WebSocket)."""
        return f'ws://{self.host}:{self.port}'

    # ------------------------------------------------------------------ feeding it

    def watch(self, source: FeederEngine | ModelParams, weigher: Weigher | None = None
              ) -> None:
        """
        Watch a run from its start: an engine (every tick of it is shown) or a model.

        A new run (an RL episode's new engine) must have the view's model (the scene's cone
        and channels are built once). The engine watched before is let go; what its run
        handed over and has not been shown yet is dropped. An engine is shown at once, as it
        is.
        """
        model = source.model if isinstance(source, FeederEngine) else source
        if isinstance(source, FeederEngine):
            weigher = source.weigher
        with self._lock:
            if self._engine is not None:
                self._engine.unobserve(self.ticked)
            self._engine = source if isinstance(source, FeederEngine) else None
            self._model = model
            self._watcher = Watcher(model, weigher)
            self._latest = None
            self._events = []
        if self._engine is not None:
            self._engine.observe(self.ticked)
            self.ticked(self._engine)

    def show(self, snapshot: Snapshot | Moment, events: Sequence[Event] = ()) -> None:
        """Hand over the newest snapshot (or moment) and the events since the last one."""
        with self._lock:
            self._latest = snapshot
            self._events.extend(events)

    def __call__(self, t: float, sim: Simulator, step: StepResult) -> None:
        """Show the runner's interval that ended at t (s): the runner's progress callback."""
        self.show(*self._watcher.interval(t, sim, step))

    def ticked(self, engine: FeederEngine, *results: TickResult) -> None:
        """
        Show the engine now, with the exits and packs of its ticks ``results``.

        The watched engine calls it after every tick (an engine observer); call it for an
        engine the view does not watch.
        """
        self.show(*self._watcher.ticks(engine, results))

    # ------------------------------------------------------------------ publishing

    def _run(self) -> None:
        due = time.monotonic()
        try:
            while not self._stop.wait(max(0.0, due - time.monotonic())):
                self._frame()
                due += self.period
                now = time.monotonic()
                if due < now - self.period:  # more than a frame late: drop the lag
                    due = now + self.period
            self._frame()  # the last state, as the run left it
        except Exception as exc:  # noqa: B902 - the run goes on; the error is kept
            self.error = exc

    def _frame(self) -> None:
        with self._lock:
            snapshot, events, watcher = self._latest, self._events, self._watcher
            self._events = []
        resend = self._resend.is_set()
        if resend:
            self._resend.clear()
        if snapshot is None or (snapshot is self._sent and not events and not resend):
            return
        start = time.monotonic()
        for event in events:
            self._channels['events'].log(self._messages.log_message(event),
                                         log_time=stamp_ns(event.t))
        if snapshot is not self._sent:
            self._sent = snapshot
            self._shown = (watcher.snapshot(snapshot) if isinstance(snapshot, Moment)
                           else snapshot)
            self._publish(self._shown)
            self.frames += 1
        elif resend and self._shown is not None:  # e.g. a client after the run's end
            self._publish(self._shown)
        self.publish_seconds += time.monotonic() - start

    def _publish(self, snapshot: Snapshot) -> None:
        t_ns = stamp_ns(snapshot.t)
        self._channels['scene'].log(self._scene.update(snapshot), log_time=t_ns)
        for key, message in self._messages.series_messages(snapshot).items():
            # Serialized here: the SDK's own JSON encoding keeps only float32's digits.
            self._channels[key].log(json.dumps(message).encode(), log_time=t_ns)
        self._server.broadcast_time(t_ns)

    # ------------------------------------------------------------------ ending

    def close(self) -> None:
        """
        Publish the last snapshot, stop the frame thread and the server; idempotent.

        An error that stopped the frame thread earlier is in :attr:`error` (not raised).
        """
        if self._stop.is_set():
            return
        if self._engine is not None:
            self._engine.unobserve(self.ticked)
        self._stop.set()
        self._thread.join()
        self._server.stop()

    def __enter__(self) -> Self:
        """Return the view."""
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        """Close the view."""
        self.close()


def _listener(sdk: ModuleType, resend: threading.Event) -> Any:
    """Return the server's listener: a subscription asks for the last frame again."""

    class Subscriptions(sdk.websocket.ServerListener):  # the SDK's no-op defaults
        def on_subscribe(self, client: 'foxglove.websocket.Client',
                         channel: 'foxglove.websocket.ChannelView') -> None:
            resend.set()

    return Subscriptions()
