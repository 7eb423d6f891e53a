"""The world server's camera reads, rendered by its render workers (issue J point 5, D103): the
methods of :class:`plugins.sim.server.WorldServer` that hand frames out and collect them.

A camera is read in one request (``read``: answered with the frame), or in two (D246): ``render``
takes the world's movable state at once and answers a ``ticket``; the frame, rendered from that
state while the world runs on, is answered to ``frame`` with the ticket. So a lock-step run's clock
waits for a render only if the frame is collected before it is made.
"""

from __future__ import annotations

import functools
import itertools
import logging
from collections.abc import Callable
from typing import Any

from .devices import ChannelDevice, SimWorld
from .render import BodyState, RenderWorker, job_of, snapshot
from .sensors import Frame
from .serving import Client, Flight, Order, frame_reply

LOG = logging.getLogger("ckm.sim.server")
MAX_ORDERS = 16  # renders a connection may have ordered and not collected
Key = tuple[int, int, float, int, int]


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
    _ordered: list[tuple[Client, Order, Key, list[BodyState]]]  # renders ordered, waiting for a worker
    _tickets: itertools.count[int]

    # ------------------------------------------------------------------ renders in two requests (D246)

    def _order(self, client: Client, device: ChannelDevice) -> dict[str, Any]:
        """``render``: the world's state now, rendered while the world runs on; the ticket to collect it."""
        key = device.camera
        if key is None:
            raise ValueError("'render' is for a camera channel (sensor rgb or depth); read the others")
        if len(client.orders) >= MAX_ORDERS:
            raise ValueError(f"{MAX_ORDERS} renders ordered and not collected on this connection")
        with self.sim.lock:
            self.sim.sync()
            world = self.sim.world
            order = Order(next(self._tickets), device, world.steps, world.time)
            if not self.renderers or key in self._unmirrored:  # no worker: rendered here, now
                order.frame = self.sim.frame(device.device, *key[3:])
            elif (kept := self.sim.kept_frame(key)) is not None:
                order.frame = kept
            elif (flight := self._flight(key, order.step)) is not None:
                flight.orders.append((client, order))
            else:
                self._ordered.append((client, order, key, snapshot(world)))
        client.orders[order.ticket] = order
        return {"ticket": order.ticket, "time": order.time}

    def _collect(self, client: Client, device: ChannelDevice, ticket: Any) -> dict[str, Any] | None:
        """``frame``: answer the ordered render now if it is made (or failed), else as soon as it is."""
        order = client.orders.get(ticket) if isinstance(ticket, int) and not isinstance(ticket, bool) else None
        if order is None or order.device is not device:
            raise ValueError(f"no render ordered with ticket {ticket!r} for this channel on this connection")
        if order.frame is None and order.error is None:
            order.awaited = True
            return None
        del client.orders[order.ticket]
        if order.frame is None:
            return order.error
        client.later(functools.partial(frame_reply, device, order.frame, order.time))
        return None

    def _withdraw(self, client: Client, device: ChannelDevice | None = None) -> None:
        """A client gone (or one of its channels closed): its renders not begun are not made; a read
        waiting for a worker is dropped only with its client, which then waits for no answer."""
        self._ordered = [i for i in self._ordered if not (i[0] is client and device in (None, i[1].device))]
        if device is None:
            self._cameras = [(c, d) for c, d in self._cameras if c is not client]

    def _flight(self, key: Key, step: int) -> Flight | None:
        return next((f for f in self._flights.values() if f.key == key and f.step == step), None)

    def _dispatch_ordered(self, idle: list[RenderWorker]) -> None:
        """Hand ordered renders to idle workers, each from the state taken when it was ordered."""
        while idle and self._ordered:
            client, order, key, state = self._ordered.pop(0)
            same = [(c, o) for c, o, k, _ in self._ordered if k == key and o.step == order.step]
            self._ordered = [item for item in self._ordered if not (item[2] == key and item[1].step == order.step)]
            flight = Flight(key, order.step, order.time, [], [(client, order), *same])
            worker = idle.pop(0)
            try:
                worker.submit(self.sim.world, job_of(order.device), state)
            except (OSError, ValueError) as exc:
                self._lose(worker, f"{type(exc).__name__}: {exc}")
                self._finish(flight, None)
                continue
            self._flights[worker] = flight

    def _deliver(self, flight: Flight, frame: Frame) -> None:
        for client, order in flight.orders:
            order.frame = frame
            if order.awaited and client in self.clients:
                client.orders.pop(order.ticket, None)
                client.later(functools.partial(frame_reply, order.device, frame, order.time))

    # ------------------------------------------------------------------ reads in one request

    def _dispatch(self) -> None:
        """Hand the waiting camera reads to the idle render workers (each with the others asking for
        the same frame), at the world's current step. A read of a frame already made at this step, or
        in flight for it, shares that render (the RGB and depth channels of one camera, D89, D240)."""
        self._share()
        idle = [worker for worker in self.renderers if not worker.busy]
        self._dispatch_ordered(idle)  # ordered first: their clients' clocks may be waiting for them
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
                flight = self._flight(key, step)
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
        device = flight.waiters[0][1] if flight.waiters else flight.orders[0][1].device
        try:
            with self.sim.lock:
                if frame is None:  # the worker could not: render here, now (an order: of the world now)
                    self.sim.sync()
                    frame = self.sim.frame(device.device, *flight.key[3:])
                else:
                    self.sim.keep_frame(flight.key, flight.step, frame)
            for client, device in flight.waiters:
                if client in self.clients:
                    client.later(functools.partial(frame_reply, device, frame, flight.time))
            self._deliver(flight, frame)
        except Exception as exc:  # never the server's end
            error = {"error": f"sim channel {device.spec.name!r}: {exc}", "type": type(exc).__name__}
            for client, _ in flight.waiters:
                self._reply(client, error)
            for client, order in flight.orders:  # the error is the ordered frame's answer
                order.error = error
                if order.awaited:
                    client.orders.pop(order.ticket, None)
                    self._reply(client, error)

    def _lose(self, worker: RenderWorker, why: str) -> None:
        self.renderers.remove(worker)
        worker.close()
        LOG.error("render worker lost (%s); %d left", why, len(self.renderers))
        if self.renderers:
            return
        ordered, self._ordered = self._ordered, []
        for client, order, key, _ in ordered:  # none left: rendered here, of the world now, as a failed flight is
            self._finish(Flight(key, order.step, order.time, [], [(client, order)]), None)
        waiting, self._cameras = self._cameras, []
        for client, device in waiting:  # none left: served here, in order
            try:
                with self.sim.lock:
                    self.sim.sync()
                    self._reply(client, {"value": device.read(), "time": self.sim.world.time})
            except Exception as exc:  # never the server's end
                self._reply(client, {"error": f"sim channel {device.spec.name!r}: {exc}", "type": type(exc).__name__})

