"""`free_port`: a port a client is told before it binds comes from below the kernel's ephemeral range, where
no other process's port-0 socket can be handed it in the meantime; it is free when returned."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from drone_inspect_core import ports
from drone_inspect_core.ports import CHOSEN_PORTS, free_port, is_free


@pytest.mark.parametrize("protocol", ["udp", "tcp"])
def test_a_free_port_is_drawn_below_the_ephemeral_range_and_is_free(protocol: str) -> None:
    ephemeral_low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    drawn = {free_port(protocol) for _ in range(20)}  # type: ignore[arg-type]
    assert all(CHOSEN_PORTS[0] <= p < min(CHOSEN_PORTS[1], ephemeral_low) for p in drawn), drawn
    assert len(drawn) > 1  # drawn at random, not one port for every caller
    assert all(is_free(p, protocol) for p in drawn)  # type: ignore[arg-type]


def test_a_held_port_is_not_drawn_and_without_the_range_the_kernel_picks(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    held = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    held.bind(("127.0.0.1", 0))
    free = next(p for p in range(*CHOSEN_PORTS) if is_free(p, "udp"))
    draws = [held.getsockname()[1], free]

    class Draws:
        """The draws free_port makes, in a fixed order (a fake for the random source alone)."""

        def randrange(self, low: int, high: int) -> int:
            return draws.pop(0)

    try:
        monkeypatch.setattr(ports.random, "SystemRandom", Draws)
        assert free_port("udp") == free  # the held one drawn first, and passed over
        monkeypatch.setattr(ports, "EPHEMERAL_RANGE_FILE", tmp_path / "none")  # not Linux: the kernel picks
        assert is_free(free_port("udp"), "udp")
    finally:
        held.close()
