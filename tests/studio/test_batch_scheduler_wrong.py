"""`--scheduler` naming something that is not a Dask scheduler a client can talk to: one line, exit 2.
Another program on the port (an SSH or web server answering first) made Dask take its first bytes
for a frame length and allocate exabytes, a MemoryError traceback; a tls:// address without Dask's
TLS settings was a TypeError traceback from inside Dask's connect."""

from __future__ import annotations

import socket
import threading
import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from puppet.cli import main
from takes import write_take


@pytest.fixture
def talker() -> Iterator[Callable[[bytes], int]]:
    """Start a TCP server on 127.0.0.1 that sends `reply` to every connection; returns its port."""
    socks: list[socket.socket] = []

    def start(reply: bytes) -> int:
        srv = socket.socket()
        srv.bind(("127.0.0.1", 0))
        srv.listen()
        socks.append(srv)

        def serve() -> None:
            while True:
                try:
                    conn, _ = srv.accept()
                except OSError:
                    return
                socks.append(conn)
                conn.sendall(reply)

        threading.Thread(target=serve, daemon=True).start()
        return srv.getsockname()[1]

    yield start
    for s in socks:
        s.close()


def _one_line(capsys: pytest.CaptureFixture, *words: str) -> str:
    _, err = capsys.readouterr()
    assert err.count("\n") == 1 and err.startswith("puppet: error:"), err
    assert all(w in err for w in words), err
    return err


@pytest.mark.parametrize("reply", [b"SSH-2.0-OpenSSH_9.2\r\n",
                                   b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n",
                                   b"\x10" + bytes(7) + b"abcdefghijklmnop"])
def test_another_program_on_the_port_is_one_line(reply: bytes, talker: Callable[[bytes], int], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    take = write_take(tmp_path / "a.jsonl", seed=2)
    address = f"tcp://127.0.0.1:{talker(reply)}"
    assert main(["batch", "export", str(take), "--out", str(tmp_path / "out"), "--to", "csv",
                 "--scheduler", address]) == 2
    _one_line(capsys, address, "not a Dask scheduler")
    assert not (tmp_path / "out" / "a.csv").exists()


def test_tls_without_dask_tls_settings_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    import dask

    for key in list(os.environ):
        if key.startswith("DASK_DISTRIBUTED__COMM__TLS"):
            monkeypatch.delenv(key)
    take = write_take(tmp_path / "a.jsonl", seed=3)
    with dask.config.set({"distributed.comm.tls.ca-file": None, "distributed.comm.tls.client.cert": None,
                          "distributed.comm.tls.client.key": None}):
        assert main(["batch", "export", str(take), "--out", str(tmp_path / "out"), "--to", "csv",
                     "--scheduler", "tls://127.0.0.1:8786"]) == 2
    _one_line(capsys, "tls://127.0.0.1:8786", "ca-file")
    with dask.config.set({"distributed.comm.tls.ca-file": str(tmp_path / "missing.pem")}):
        assert main(["batch", "export", str(take), "--out", str(tmp_path / "out"), "--to", "csv",
                     "--scheduler", "tls://127.0.0.1:8786"]) == 2
    _one_line(capsys, "tls://127.0.0.1:8786", "TLS settings")
