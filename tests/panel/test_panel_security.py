"""Security of the page's server on real loopback sockets: the LAN mode's token, the loopback
mode's Host check, WebSocket origins, and file names that try to leave the take folder."""

from __future__ import annotations

import asyncio
import http.client
import json
import os
import subprocess
import sys
from pathlib import Path

import aiohttp
import devices
import pytest
from panel_browser import CHILD_ENV, ROOT

SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"


def get(port: int, path: str, headers: dict[str, str] | None = None) -> tuple[int, dict[str, str], bytes]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        c.request("GET", path, headers=headers or {})
        r = c.getresponse()
        return r.status, dict(r.getheaders()), r.read()
    finally:
        c.close()


def ws_status(url: str, origin: str | None = None, cookies: dict[str, str] | None = None) -> int:
    async def go() -> int:
        headers = {"Origin": origin} if origin else {}
        async with aiohttp.ClientSession(cookies=cookies) as s:
            try:
                async with s.ws_connect(url, headers=headers) as ws:
                    msg = await ws.receive(timeout=5)
                    assert json.loads(msg.data)["t"] == "hello"
                    return 101
            except aiohttp.WSServerHandshakeError as err:
                return err.status

    return asyncio.run(go())


@pytest.fixture
def lan_page():
    dev = devices.open_device("panel://127.0.0.1:0?lan=1")  # LAN mode, but on the loopback in tests
    yield dev
    dev.close()


@pytest.fixture
def local_page():
    dev = devices.open_device("panel://127.0.0.1:0")
    yield dev
    dev.close()


def test_lan_server_serves_nothing_without_the_token(lan_page) -> None:
    srv = lan_page.server
    port, token = srv.port, srv.token
    assert token and len(token) >= 16 and f"token={token}" in lan_page.url
    for path in ("/", "/static/panel.js", "/api/layout", "/ws", "/nope"):
        status, _, body = get(port, path)
        assert status == 403 and b"token" in body
    assert get(port, "/?token=wrong" + token[5:])[0] == 403
    status, headers, body = get(port, f"/?token={token}")
    assert status == 200 and b"performer" in body
    cookie = headers["Set-Cookie"].split(";")[0]
    assert "HttpOnly" in headers["Set-Cookie"] and "SameSite=Strict" in headers["Set-Cookie"]
    assert get(port, "/static/panel.js", {"Cookie": cookie})[0] == 200
    assert ws_status(f"http://127.0.0.1:{port}/ws") == 403
    assert ws_status(f"http://127.0.0.1:{port}/ws?token={token}") == 101


def test_loopback_server_refuses_foreign_hosts_and_origins(local_page) -> None:
    port = local_page.server.port
    assert local_page.url == f"http://127.0.0.1:{port}/"
    assert get(port, "/")[0] == 200
    assert get(port, "/", {"Host": "attacker.example"})[0] == 403  # DNS rebinding
    assert get(port, "/", {"Host": f"attacker.example:{port}"})[0] == 403
    assert ws_status(f"http://127.0.0.1:{port}/ws", origin="http://attacker.example") == 403
    assert ws_status(f"http://127.0.0.1:{port}/ws", origin=f"http://127.0.0.1:{port}") == 101
    cross = {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "no-cors"}
    assert get(port, "/api/layout", cross)[0] == 403 and get(port, "/static/panel.js", cross)[0] == 403
    assert get(port, "/", {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate"})[0] == 200  # a link
    assert local_page.server.refused >= 5


def test_static_files_cannot_be_escaped(local_page) -> None:
    port = local_page.server.port
    for path in ("/static/../server.py", "/static/..%2fserver.py", "/static/%2e%2e%2f%2e%2e%2fcli.py",
                 "/static/..%5cserver.py", "/static/", "/static/style.css%00.js", "/static//etc/passwd"):
        status, _, body = get(port, path)
        assert status in (403, 404), path
        assert b"import" not in body and b"root:" not in body


@pytest.fixture(scope="module")
def editor(tmp_path_factory: pytest.TempPathFactory):
    from puppet.panel.editor import Editor
    from puppet.panel.server import PanelServer

    d = tmp_path_factory.mktemp("sec")
    subprocess.run([sys.executable, "-m", "puppet", "live", "--device", f"mock://{SCRIPT}?speed=0", "--headless",
                    "--duration", "1", "--record", "take.jsonl"], cwd=d, check=True, capture_output=True,
                   env=CHILD_ENV)
    outside = d.parent / f"{d.name}-outside"
    outside.mkdir()
    (d / "link.curves").symlink_to(outside / "stolen.curves")
    ed = Editor(d / "take.jsonl")
    srv = PanelServer("127.0.0.1", 0, "editor.html", ed.routes)
    srv.start()
    yield srv.port, d, outside
    srv.stop()
    ed.close()


def post(port: int, path: str, body: object, origin: str | None = None) -> tuple[int, dict]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    headers = {"Content-Type": "application/json"}
    if origin:
        headers["Origin"] = origin
    try:
        c.request("POST", path, body=json.dumps(body), headers=headers)
        r = c.getresponse()
        raw = r.read()
        try:
            return r.status, json.loads(raw)
        except ValueError:
            return r.status, {"text": raw.decode(errors="replace")}
    finally:
        c.close()


CURVES = [{"target": "jaw", "interp": "linear", "mode": "replace", "keys": [[0.1, 0.2], [0.5, 0.6, "step"]]}]


def test_editor_writes_only_inside_the_take_folder(editor) -> None:
    port, d, outside = editor
    before = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()}
    for name in ("../evil.curves", "/tmp/evil.curves", "..\\evil.curves", "sub/evil.curves", ".hidden.curves",
                 "take.jsonl", "evil.curves\0.txt", "link.curves", "x" * 300 + ".curves", 7):
        status, reply = post(port, "/api/curves", {"curves": CURVES, "save": True, "name": name})
        assert status == 400 and not reply["ok"], name
    for name in ("../evil.mp4", "/tmp/evil.csv", "take.jsonl", "evil.txt"):
        status, reply = post(port, "/api/export", {"name": name})
        assert status == 400 and not reply["ok"], name
    assert not (outside / "stolen.curves").exists() and not list(outside.iterdir())
    assert not Path("/tmp/evil.curves").exists()
    after = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()}
    assert after == before  # nothing written, the take untouched
    status, reply = post(port, "/api/curves", {"curves": CURVES, "save": True, "name": "ok.curves"})
    assert status == 200 and reply["saved"] == "ok.curves" and (d / "ok.curves").exists()
    assert post(port, "/api/curves", {"curves": CURVES}, origin="http://attacker.example")[0] == 403


def test_editor_rejects_damaged_curves_with_one_reason(editor) -> None:
    import random

    port, _, _ = editor
    rng = random.Random(13)
    bad_values = [None, "x", [], {}, -1, 1e309, float("nan"), True, [[1]], [["a", 1]], "linear", 10**7]
    for _ in range(60):
        body = json.loads(json.dumps(CURVES))
        c = body[0]
        where = rng.choice(["target", "interp", "mode", "keys", "key", "value", "seg", "order"])
        v = rng.choice(bad_values)
        if where in ("target", "interp", "mode", "keys"):
            c[where] = v
        elif where == "key":
            c["keys"][0] = v
        elif where == "value":
            c["keys"][0][rng.randrange(2)] = v
        elif where == "seg":
            c["keys"][1][2] = "bezier"
        else:
            c["keys"].reverse()
        try:
            text = json.dumps({"curves": body})
        except ValueError:
            continue
        status, reply = post(port, "/api/curves", json.loads(text) if "NaN" not in text else {"curves": "x"})
        if status == 200:  # a variant that stayed valid (e.g. a value that is still a number)
            continue
        assert status == 400 and reply["ok"] is False and "\n" not in reply["error"]
    status, reply = post(port, "/api/curves", {"curves": [{"target": "smirk", "keys": [[0, 1]]}]})
    assert status == 400 and "smirk" in reply["error"]


def test_edit_command_errors_are_one_line(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("DISPLAY", None)
    bad = tmp_path / "bad.jsonl"
    bad.write_bytes(b"\x00\xffnot a take\n")
    for args in (["edit", str(tmp_path / "missing.jsonl")], ["edit", str(bad)], ["live", "--panel", "70000", "--headless"]):
        r = subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True, env=env, timeout=120)
        assert r.returncode == 2, (args, r.stderr)
        assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_a_page_port_out_of_range_speaks_of_the_option(tmp_path: Path) -> None:
    """`--panel 99999` is refused in the user's own words (the option and the number typed), before
    the face loads: it printed the page device's error about a panel:// URL nobody typed."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PUPPET_LIBRARY="off")
    env.pop("DISPLAY", None)
    for port in ("99999", "-1"):
        for extra in ([], ["--panel-lan"]):
            r = subprocess.run([sys.executable, "-m", "puppet", "live", "--panel", port, "--duration", "1", *extra],
                               capture_output=True, text=True, env=env, timeout=120, cwd=tmp_path)
            assert r.returncode == 2, r.stderr
            assert r.stderr.count("\n") == 1 and f"--panel {port}" in r.stderr and "panel://" not in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []  # no recording started, no picture left


def test_no_panel_with_a_page_option_is_one_line(tmp_path: Path) -> None:
    """`--no-panel --panel 9000` (or with --panel-lan, --panel-role) served no page and said nothing
    of the page option given: one line naming both, before the face loads, nothing written."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), PUPPET_LIBRARY="off")
    env.pop("DISPLAY", None)
    for extra in (["--panel", "0"], ["--panel-lan"], ["--panel-role", "mouth=jaw"]):
        r = subprocess.run([sys.executable, "-m", "puppet", "live", "--no-panel", *extra, "--duration", "1"],
                           capture_output=True, text=True, env=env, timeout=120, cwd=tmp_path)
        assert r.returncode == 2, r.stderr
        assert r.stderr.count("\n") == 1 and "--no-panel" in r.stderr and extra[0] in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_page_port_in_use_is_one_line(tmp_path: Path) -> None:
    """Another program holds the page's port: one line and exit 2, no asyncio complaint about the
    page's broadcast task after it."""
    import socket

    env = dict(os.environ, PYTHONPATH=str(ROOT), PUPPET_LIBRARY="off")
    env.pop("DISPLAY", None)
    script = tmp_path / "s.toml"
    script.write_text('impersonate = "sgi"\nduration = 1.0\n')
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        r = subprocess.run([sys.executable, "-m", "puppet", "live", "--headless", "--device", f"mock://{script}",
                            "--duration", "1", "--panel", str(port)],
                           capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "in use" in r.stderr, r.stderr


def test_a_restarted_server_binds_its_port_again_while_the_pages_closed_connections_linger() -> None:
    """A show stopped (or crashed) while a page was connected leaves that connection in TIME_WAIT
    on the page's port for a minute; the show started again must serve the same port, where the
    open pages retry (it failed 'address already in use' for a fixed --panel PORT, and moved the
    default port to the next one, where no page looks)."""
    from puppet.panel.server import PanelServer

    first = PanelServer("127.0.0.1", 0, "panel.html", lambda app: None)
    first.start()
    port = first.port
    page = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    page.request("GET", "/")  # a keep-alive connection, open when the server goes
    assert page.getresponse().read()
    first.stop()  # the server closes it first: its end waits in TIME_WAIT on `port`
    page.close()
    again = PanelServer("127.0.0.1", port, "panel.html", lambda app: None, try_ports=5)
    try:
        again.start()
        assert again.port == port
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        c.request("GET", "/")
        assert c.getresponse().status == 200
        c.close()
    finally:
        again.stop()


@pytest.mark.parametrize("host", ["127.0.0.2", "[::1]"])
def test_a_page_on_another_loopback_address_is_served_at_its_url(host: str) -> None:
    """panel://127.0.0.2:PORT printed its URL and refused every request to it ('served to the
    loopback address only'); panel://[::1]:PORT did not start ('Name or service not known; pick
    another port'). Both serve their URL; a foreign Host is still refused."""
    import socket

    from puppet.panel.server import PanelServer

    if host.startswith("["):
        try:
            with socket.socket(socket.AF_INET6) as s6:
                s6.bind(("::1", 0))
        except OSError:
            pytest.skip("no IPv6 loopback on this machine")
    srv = PanelServer(host, 0, "panel.html", lambda app: None)
    url = srv.start()
    try:
        assert url == f"http://{host}:{srv.port}/"
        c = http.client.HTTPConnection(host.strip("[]"), srv.port, timeout=30)
        c.request("GET", "/")  # Host: HOST:PORT, as a browser sends it for the URL
        assert c.getresponse().status == 200
        c.close()
        c = http.client.HTTPConnection(host.strip("[]"), srv.port, timeout=30)
        c.request("GET", "/", headers={"Host": f"evil.example:{srv.port}"})
        assert c.getresponse().status == 403
        c.close()
    finally:
        srv.stop()


def test_lan_url_is_printed_with_a_qr_code(lan_page) -> None:
    import io

    from puppet.panel import announce

    out = io.StringIO()
    announce(lan_page, out)
    text = out.getvalue()
    assert f"token={lan_page.server.token}" in text
    assert sum(text.count(c) for c in "█▀▄") > 100  # the QR code in block characters


def test_editor_answers_a_body_nested_thousands_deep_with_one_reason(editor) -> None:
    """A POST body of 100000 nested arrays (within the 1 MB limit): json's RecursionError was a
    500 with a traceback on the editor's terminal. It is a 400 naming why, and the editor serves on."""
    port, d, _ = editor
    before = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()}
    for path in ("/api/curves", "/api/export"):
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
        try:
            c.request("POST", path, body="[" * 100_000 + "]" * 100_000, headers={"Content-Type": "application/json"})
            r = c.getresponse()
            reply = json.loads(r.read())
        finally:
            c.close()
        assert r.status == 400 and reply["ok"] is False and "nested too deep" in reply["error"], (path, reply)
    assert {p.name: p.read_bytes() for p in d.iterdir() if p.is_file()} == before
    assert post(port, "/api/curves", {"curves": CURVES})[0] == 200


def test_edit_a_take_with_no_tick_is_one_line(tmp_path: Path) -> None:
    """A take holding its header only (the show stopped before its first tick): the editor opened
    on it and its export answered 500 with an IndexError traceback. `puppet edit` says there is
    nothing to edit, one line (and the end-record warning), exit 2."""
    header = (ROOT / "tests" / "puppet" / "data" / "take_jaw_whole.jsonl").read_text().splitlines()[0]
    take = tmp_path / "stopped.jsonl"
    take.write_text(header + "\n")
    r = subprocess.run([sys.executable, "-m", "puppet", "edit", str(take), "--duration", "5"], capture_output=True,
                       text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert r.returncode == 2 and len(errors) == 1 and "nothing to edit" in errors[0], r.stdout + r.stderr
    assert "Traceback" not in r.stderr and not list(tmp_path.glob("*.curves"))


@pytest.mark.parametrize("spec", ["panel://0.0.0.0:0", "panel://[::]:0"])
def test_a_page_beyond_the_loopback_needs_lan_1(spec: str) -> None:
    """`--device panel://0.0.0.0:PORT` served every interface with no token: its only guard was the
    Host header, which a machine on the network writes as 127.0.0.1 as easily as a browser here.
    It is refused, as a UDP device's address beyond the loopback is, naming lan=1."""
    with pytest.raises(devices.DeviceError, match="lan=1"):
        dev = devices.open_device(spec)
        dev.close()


def test_a_page_named_as_a_device_prints_its_url(tmp_path: Path) -> None:
    """`puppet live --device 'panel://127.0.0.1:0?lan=1'` served the page behind a token it never
    printed: nobody could open it. Its URL is printed like the default page's."""
    r = subprocess.run([sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--duration", "1",
                        "--device", "panel://127.0.0.1:0?lan=1"], cwd=tmp_path, capture_output=True, text=True,
                       env=CHILD_ENV, timeout=300)
    assert r.returncode == 0, r.stderr
    urls = [ln for ln in r.stdout.splitlines() if "performer's page at http://127.0.0.1:" in ln]
    assert len(urls) == 1 and "?token=" in urls[0], r.stdout
