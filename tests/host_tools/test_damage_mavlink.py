"""Damage telemetry end to end: propid_sitl flies a quad that loses 30 % of rotor 3
in flight with the detector on and sends MAVLink over UDP on this machine; the
firmware's packer (propid_mavlink_pack_damage_alert) must put a PROPID_DAMAGE and a
CRITICAL STATUSTEXT on the wire that the host decoder (propid.mavlink_io) reads back
as the detection the simulator reports, and the live view shows it.

The simulator binary comes from PROPID_BUILD_DIR (default <repo>/build/host); see
conftest.py for the skip / fail rule.
"""

from __future__ import annotations

import subprocess

import pytest

from propid import mavlink_io
from propid.commands import listen

def test_damage_alert_crosses_the_link(tmp_path, sitl_binary, free_udp_port):
    port = free_udp_port()
    conn = mavlink_io.connect(f"udp:127.0.0.1:{port}")
    summary = tmp_path / "summary.json"
    sitl = subprocess.Popen(
        [str(sitl_binary), "--vehicle", "crazyflie-plus", "--trajectory", "lissajous", "--mode", "filter",
         "--paper", "--duration", "3", "--seed", "4", "--realtime", "5", "--detect-damage",
         "--damage", "3@2.2=0.3", "--mavlink", f"udp:127.0.0.1:{port}",
         "--summary-json", str(summary), "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    damage, texts = [], []
    try:
        while sitl.poll() is None or len(damage) < 1:
            msg = conn.recv_match(type=["PROPID_DAMAGE", "STATUSTEXT"], blocking=True, timeout=5)
            if msg is None:
                break
            if msg.get_type() == "PROPID_DAMAGE":
                damage.append(mavlink_io.damage_event(msg))
            else:
                texts.append(mavlink_io.statustext(msg))
        # the STATUSTEXT follows its PROPID_DAMAGE in the same datagram burst
        while len(texts) < len(damage):
            msg = conn.recv_match(type="STATUSTEXT", blocking=True, timeout=2)
            if msg is None:
                break
            texts.append(mavlink_io.statustext(msg))
    finally:
        conn.close()
        try:
            _, err = sitl.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            sitl.kill()
            _, err = sitl.communicate()
    assert sitl.returncode == 0, err
    import json

    detections = json.loads(summary.read_text())["detections"]
    assert detections and detections[0]["rotor"] == 3, detections
    assert damage, "no PROPID_DAMAGE on the link"
    first = damage[0]
    assert first["rotor"] == 3 and first["detections"] == 1 and first["damaged_rotors"] == [3]
    assert 2.2 <= first["time_s"] <= 2.25
    assert first["time_s"] == pytest.approx(detections[0]["time_s"], abs=2e-3)
    assert texts[0] == (mavlink_io.MAV_SEVERITY_CRITICAL, "propid: rotor 3 damaged, re-identifying")
    line = mavlink_io.format_damage_event(first)
    assert "rotor 3" in line and "damaged rotors 3" in line


def test_damage_decoder_on_an_encoded_frame():
    frame = mavlink_io.encode_message("PROPID_DAMAGE", time_usec=5_250_000, rotor=6, detections=2,
                                      damaged_mask=0b100010)
    msg = mavlink_io.dialect().MAVLink(None).parse_char(frame)
    event = mavlink_io.damage_event(msg)
    assert event == {"time_s": 5.25, "rotor": 6, "detections": 2, "damaged_rotors": [2, 6]}
    view = listen.format_view(None, None, None, 1, "test", damage=[mavlink_io.format_damage_event(event)])
    assert view.splitlines()[-1] == "DAMAGE t=5.250 s: rotor 6 (detection 2; damaged rotors 2, 6)"
