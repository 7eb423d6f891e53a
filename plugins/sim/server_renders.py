"""The world server's camera reads, rendered by its render workers (issue J point 5, D103): the
methods of :class:`plugins.sim.server.WorldServer` that hand frames out and collect them."""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from typing import Any

from .devices import ChannelDevice, SimWorld
from .render import RenderWorker, job_of
from .sensors import Frame
from .serving import Client, Flight, frame_reply

LOG = logging.getLogger("ckm.sim.server")


class RenderDispatch:
    """Camera reads waiting for a render worker, the frames in flight, and their answers."""

    sim: SimWorld
    renderers: list[RenderWorker]
    clients: list[Client]
    _cameras: list[tuple[Client, ChannelDevice]]
    _flights: dict[RenderWorker, Flight]
    _unmirrored: set[tuple[int, int, float, int, int]]
    _reply: Callable[[Client, dict[str, Any]], None]
    """Answer one client (the server's)."""

    def _dispatch(self) -> None:
        """Hand the waiting camera reads to the idle render workers (each with the others asking for
        the same frame), at the world's current step. A read of a frame already made at this step, or
        in flight for it, shares that render (the RGB and depth channels of one camera, D89, D240)."""
        self._share()
        idle = [worker for worker in self.renderers if not worker.busy]
        while idle and self._cameras:
            worker = idle.pop(0)
            client, device = self._cameras.pop(0)
            key = device.camera
            assert key is not None
            with self.sim.lock:
                self.sim.sync()
                world = self.sim.world
                flight = Flight(key, world.steps, world.time, [(client, device)])
                flight.waiters += [(c, d) for c, d in self._cameras if d.camera == key]
                self._cameras = [(c, d) for c, d in self._cameras if d.camera != key]
                try:
                    worker.submit(world, job_of(device))
                except (OSError, ValueError) as exc:
                    self._lose(worker, f"{type(exc).__name__}: {exc}")
                    self._finish(flight, None)
                    continue
            self._flights[worker] = flight

    def _share(self) -> None:
        if not self._cameras:
            return
        waiting: list[tuple[Client, ChannelDevice]] = []
        with self.sim.lock:
            self.sim.sync()
            step, now = self.sim.world.steps, self.sim.world.time
            for client, device in self._cameras:
                key = device.camera
                assert key is not None
                frame = self.sim.kept_frame(key)
                flight = next((f for f in self._flights.values() if f.key == key and f.step == step), None)
                if frame is not None:
                    client.later(functools.partial(frame_reply, device, frame, now))
                elif flight is not None:
                    flight.waiters.append((client, device))
                else:
                    waiting.append((client, device))
        self._cameras = waiting

    def _landed(self, worker: RenderWorker) -> None:
        flight, result = self._flights.pop(worker), worker.result()
        if isinstance(result, str):
            LOG.warning("render worker: %s; this camera renders in the physics thread", result)
            self._unmirrored.add(flight.key)
            if not worker.alive():
                self._lose(worker, result)
        self._finish(flight, result if isinstance(result, Frame) else None)

    def _finish(self, flight: Flight, frame: Frame | None) -> None:
        client, device = flight.waiters[0]
        try:
            with self.sim.lock:
                if frame is None:  # the worker could not: render here, now
                    self.sim.sync()
                    frame = self.sim.frame(device.device, *flight.key[3:])
                else:
                    self.sim.keep_frame(flight.key, flight.step, frame)
            for client, device in flight.waiters:
                if client in self.clients:
                    client.later(functools.partial(frame_reply, device, frame, flight.time))
        except Exception as exc:  # never the server's end
            for client, device in flight.waiters:
                self._reply(client, {"error": f"sim channel {device.spec.name!r}: {exc}", "type": type(exc).__name__})

    def _lose(self, worker: RenderWorker, why: str) -> None:
        self.renderers.remove(worker)
        worker.close()
        LOG.error("render worker lost (%s); %d left", why, len(self.renderers))
        if self.renderers:
            return
        waiting, self._cameras = self._cameras, []
        for client, device in waiting:  # none left: served here, in order
            try:
                with self.sim.lock:
                    self.sim.sync()
                    self._reply(client, {"value": device.read(), "time": self.sim.world.time})
            except Exception as exc:  # never the server's end
                self._reply(client, {"error": f"sim channel {device.spec.name!r}: {exc}", "type": type(exc).__name__})

