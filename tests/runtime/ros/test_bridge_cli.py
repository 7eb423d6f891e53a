"""``ckm-ros-bridge``: a CKM system's ROS-typed topics seen and heard by an rmw_zenoh node (issue L, D159).

The bridge command runs as its own process on a private CKMultiPeer network; a Zenoh session in
peer mode listening on 127.0.0.1 plays the ROS side's router and node: it must see the bridge's
liveliness tokens (the node, a publisher and a subscription per topic of configs/examples/
sim_ros_types.xml), and a LaserScan it puts on ``/scan`` the rmw_zenoh way (CDR, 33-byte attachment)
must reach a CKM subscriber of ``/scan``; and the simulated Turtlebot's scans (ckm-run of the example)
reach that node through the bridge as CDR LaserScans in ``hokuyo_link``.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from rosbags.typesys import Stores, get_typestore

import ckmconf
from runtime.network import Transport
from runtime.network.api import TopicQoS
from runtime.resources import codec
from runtime.ros.convert import encode_payload
from runtime.ros.rmw_zenoh import Attachment, encode_attachment, topic_keyexpr
from runtime.ros.types import RosTypes
from runtime.ros.wire import install
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network, transports  # noqa: F401 (fixture)
from tests.runtime.ros.test_rmw_zenoh_live import _config, _free_port

EXAMPLE = REPO / "configs" / "examples" / "sim_ros_types.xml"
TOPICS = 8  # the example's external topics of a ROS 2 type


def _example_on_private_network(tmp_path: Path) -> tuple[Any, Path]:
    """The ROS-typed example written to ``tmp_path`` on a private loopback network, and that network."""
    net = private_network("multipeer")
    element = (f'<Network interface="127.0.0.1" group="{net.group}" discoveryPort="{net.discovery_port}" '
               f'basePort="{net.base_port}"/>')
    config = tmp_path / EXAMPLE.name
    config.write_text(re.sub(r"(<System [^>]*>)", lambda m: m.group(1) + "\n  " + element, EXAMPLE.read_text(),
                             count=1))
    return net, config


@pytest.mark.timeout(90)
def test_the_bridge_command_shows_ckm_topics_to_ros_and_brings_ros_samples_in(
    tmp_path: Path, transports: Callable[..., Transport]  # noqa: F811
) -> None:
    net, config = _example_on_private_network(tmp_path)
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    ros_side = zenoh.open(_config([endpoint], []))
    ckm = transports(net, "listener")
    install(ckm, ckmconf.load(config))  # CDR on the wire, as ckm-run and the bridge send ROS types
    heard = ckm.subscribe(TopicQoS("/scan", "sensor_msgs/msg/LaserScan", "best-effort", 5, None, None))
    bridge = subprocess.Popen(
        [sys.executable, "-m", "runtime.ros.bridge_cli", str(config), "--router", endpoint, "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
    )
    try:
        deadline, tokens = time.monotonic() + 40, list[str]()
        while time.monotonic() < deadline and len(tokens) < 1 + 2 * TOPICS:
            tokens = [str(r.ok.key_expr) for r in ros_side.liveliness().get("@ros2_lv/0/**", timeout=1.0) if r.ok]
            time.sleep(0.1)
        assert len(tokens) == 1 + 2 * TOPICS, tokens
        assert any("/MP/" in t and "%scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_" in t for t in tokens)
        assert any("/MS/" in t and "%tf/tf2_msgs::msg::dds_::TFMessage_/RIHS01_" in t for t in tokens)

        ros = RosTypes()
        key = topic_keyexpr(0, "/scan", "sensor_msgs/msg/LaserScan", ros.rihs01("sensor_msgs/msg/LaserScan"))
        scan = {"header": {"stamp": 1700000000.25, "frame_id": "laser"}, "ranges": np.linspace(0.5, 2.0, 4)}
        payload = encode_payload(ros, "sensor_msgs/msg/LaserScan", scan)
        deadline, seq = time.monotonic() + 30, 0
        while time.monotonic() < deadline and heard.latest() is None:  # until the bridge's peer joined ours
            seq += 1
            attachment = encode_attachment(Attachment(seq, time.time_ns(), bytes(range(16))))
            ros_side.put(key, payload, attachment=attachment)
            time.sleep(0.2)
        sample = heard.latest()
        assert sample is not None, "the CKM subscriber heard nothing from the ROS side"
        value = codec.decode(sample.value)  # the codec's plain form, as every CKM consumer reads it (D194)
        assert value["header"]["frame_id"] == "laser"
        assert np.allclose(value["ranges"], [0.5, 1.0, 1.5, 2.0])
    finally:
        bridge.send_signal(signal.SIGTERM)
        out, err = bridge.communicate(timeout=30)
        ros_side.close()  # type: ignore[no-untyped-call]
    assert bridge.returncode == 0, err
    lines = out.splitlines()
    assert f"bridging /scan [sensor_msgs/msg/LaserScan] as {key}" in lines
    statistics = json.loads(lines[-1])
    assert set(statistics) == {"/scan", "/camera/rgb/image_raw", "/camera/rgb/camera_info", "/camera/depth/image_raw",
                               "/camera/depth/camera_info", "/joint_states", "/odom", "/tf"}
    assert statistics["/scan"]["toCkm"] >= 1 and statistics["/scan"]["dropped"] == 0


@pytest.mark.timeout(120)
def test_a_ros_node_receives_the_simulated_scan_through_the_bridge(tmp_path: Path) -> None:
    _, config = _example_on_private_network(tmp_path)
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    ros_side = zenoh.open(_config([endpoint], []))
    heard: list[zenoh.Sample] = []
    listener = ros_side.declare_subscriber("0/scan/**", heard.append)
    try:
        bridge = subprocess.Popen(
            [sys.executable, "-m", "runtime.ros.bridge_cli", str(config), "--router", endpoint, "--topics", "/scan,/tf",
             "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        )
        try:
            run = subprocess.run(
                [sys.executable, "-m", "runtime.cli", str(config), "--duration", "4", "--log-dir", str(tmp_path / "r")],
                capture_output=True, text=True, timeout=90, cwd=REPO,
            )
        finally:
            bridge.send_signal(signal.SIGTERM)
            out, err = bridge.communicate(timeout=30)
        assert run.returncode == 0, run.stderr
        assert bridge.returncode == 0, err
        listener.undeclare()  # type: ignore[no-untyped-call]
    finally:
        ros_side.close()  # type: ignore[no-untyped-call]
    assert heard, "the ROS node heard no scan"
    store = get_typestore(Stores.ROS2_JAZZY)
    message: Any = store.deserialize_cdr(heard[-1].payload.to_bytes(), "sensor_msgs/msg/LaserScan")
    assert message.header.frame_id == "hokuyo_link" and len(message.ranges) == 683
    assert heard[-1].attachment is not None and len(heard[-1].attachment.to_bytes()) == 33
    statistics = json.loads(out.splitlines()[-1])
    assert statistics["/scan"]["toRos"] == len(heard) and statistics["/tf"]["toRos"] > 0


def test_a_system_without_ros_topics_is_refused(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "runtime.ros.bridge_cli", str(REPO / "configs" / "examples" / "closed_loop.xml"),
         "--duration", "0"], capture_output=True, text=True, timeout=60, cwd=REPO,
    )
    assert done.returncode == 1 and "no external topic of a ROS 2 type" in done.stderr
