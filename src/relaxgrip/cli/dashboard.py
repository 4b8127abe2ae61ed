"""``relaxgrip dashboard``: the live web dashboard on the twin, the emulator or a rig."""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import re
import signal
import socket
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, Any

import typer

from relaxgrip.cli._app import app, console, int_option
from relaxgrip.cli._twin import MaterialOption, RigOption, twin_config
from relaxgrip.dashboard.access import is_loopback
from relaxgrip.errors import InputError

__all__ = ["check_host", "check_tls", "dashboard", "is_loopback"]


#: A DNS label (RFC 1123): letters, digits and inner hyphens, at most 63 characters.
_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")


def check_host(host: str) -> str:
    """Return ``host`` if it is an IP address or a well-formed host name (not looked up).

    Raises
    ------
    InputError
        Anything else: spaces, an empty name, ``999.1.1.1`` (no address, and a name's
        last label is never all digits).
    """
    if host == "localhost":
        return host
    try:
        ipaddress.ip_address(host)
        return host
    except ValueError:
        pass
    labels = host.removesuffix(".").split(".")
    if not (len(host) <= 253 and all(_LABEL.fullmatch(label) for label in labels)
            and not labels[-1].isdigit()):
        raise InputError(f"--host {host!r} is an invalid host: give an IP address "
                         "(127.0.0.1, ::1) or a host name")
    return host


@app.command("dashboard")
def dashboard(
    backend: Annotated[str, typer.Option(
        "--backend", help="twin, emulator (the twin behind the MCU emulator) or "
                          "serial:RIG.toml (a real gripper).")] = "twin",
    host: Annotated[str, typer.Option("--host", help="Address to bind.")] = "127.0.0.1",
    port: Annotated[int, int_option("--port", help="TCP port.")] = 8000,
    allow_remote: Annotated[bool, typer.Option(
        "--allow-remote", help="Allow a non-loopback --host; needs --certfile and --keyfile "
                               "(TLS) or --insecure-remote.")] = False,
    token: Annotated[str | None, typer.Option(
        "--token", envvar="RELAXGRIP_TOKEN",
        help="Access token the page, the API and the WebSocket need (8-256 letters, digits "
             "and ._~-; default: a new random one on every start, printed in the URL).",
        show_default=False)] = None,
    certfile: Annotated[Path | None, typer.Option(
        "--certfile", help="TLS certificate (PEM): serve https and wss.",
        show_default=False)] = None,
    keyfile: Annotated[Path | None, typer.Option(
        "--keyfile", help="Private key of --certfile (PEM).", show_default=False)] = None,
    insecure_remote: Annotated[bool, typer.Option(
        "--insecure-remote", help="With --allow-remote, serve plain http: the token and "
                                  "every control cross the network unencrypted.")] = False,
    estimator: Annotated[str, typer.Option(
        "--estimator", help="fixed, icfn, relax or observer (the default: it follows a "
                            "mode switch while holding, which relax's Eq. 10 does not).")
    ] = "observer",
    seed: Annotated[int, int_option("--seed", help="Twin seed.")] = 0,
    record_dir: Annotated[Path, typer.Option(
        "--record-dir", help="Where MCAP recordings go.")] = Path("."),
    models: Annotated[Path | None, typer.Option(
        "--models", help="Model directory (relaxgrip train; default: the shipped models).",
        show_default=False)] = None,
    observer_dir: Annotated[Path | None, typer.Option(
        "--observer", help="Observer directory (relaxgrip fit-observer; default: the shipped "
                           "observer).", show_default=False)] = None,
    rig: RigOption = None,
    material: MaterialOption = None,
) -> None:
    """Serve the live dashboard and run the gripper loop in real time (30 Hz) behind it."""
    from relaxgrip.dashboard import require_web_stack

    require_web_stack()
    if not 0 < port < 65536:
        raise InputError(f"--port must be 1-65535, got {port}")
    check_host(host)
    from relaxgrip.dashboard.access import check_token, new_token

    access_token = new_token() if token is None else check_token(token)
    address = _resolve(host, port)  # a name that does not resolve: said before --allow-remote
    remote = not is_loopback(host)
    if remote and not allow_remote:
        raise InputError(f"--host {host} is reachable from other machines: add --allow-remote "
                         "(with --certfile/--keyfile for TLS, or --insecure-remote)")
    if insecure_remote and not allow_remote:
        raise InputError("--insecure-remote is for --allow-remote: a loopback dashboard "
                         "needs no permission to serve plain http")
    tls = check_tls(certfile, keyfile)
    if remote and tls is None and not insecure_remote:
        raise InputError(f"--host {host} with --allow-remote needs TLS: give --certfile and "
                         "--keyfile, or --insecure-remote to send the token and the controls "
                         "unencrypted")
    import uvicorn

    from relaxgrip.clock import WallClock
    from relaxgrip.dashboard.app import create_app
    from relaxgrip.dashboard.session import open_session

    config = None if rig is None and material is None else twin_config(rig, material=material)
    listener = _bind(address, host, port)  # a port in use is known before anything starts
    try:
        session = open_session(backend, clock=WallClock(), seed=seed, estimator=estimator,
                               record_dir=record_dir, models_dir=models,
                               observer_dir=observer_dir, config=config)
    except BaseException:
        listener.close()
        raise
    application = create_app(session, token=access_token, loopback_only=not remote)
    shown = f"[{host}]" if ":" in host else host
    url = f"{'https' if tls else 'http'}://{shown}:{port}/?token={access_token}"
    console.print(f"dashboard ({session.backend.info.name}) on {url}", markup=False,
                  highlight=False, soft_wrap=True)
    console.print("open that URL (it holds the access token); Ctrl-C stops the dashboard "
                  "(motor stopped, heaters off)", markup=False, highlight=False)
    server_log = logging.getLogger("uvicorn.error")
    invalid_text = _InvalidTextFilter()
    try:
        # No proxy headers: a loopback client's X-Forwarded-* would be believed otherwise.
        server_config = uvicorn.Config(application, log_level="warning", proxy_headers=False,
                                ssl_certfile=None if tls is None else str(tls[0]),
                                ssl_keyfile=None if tls is None else str(tls[1]))
        server = _hangup_server(server_config)
        server_log.addFilter(invalid_text)  # after the Config, which sets up uvicorn's logging
        server.run(sockets=[listener])
    finally:
        server_log.removeFilter(invalid_text)
        session.close()
        listener.close()


def check_tls(certfile: Path | None, keyfile: Path | None) -> tuple[Path, Path] | None:
    """The certificate and key to serve TLS with, once they load; None without them.

    Raises
    ------
    InputError
        One of the two without the other, a file that is missing or not a
        regular file, or a pair that does not load (not PEM, a key that is not
        the certificate's, a key with a passphrase).
    """
    if certfile is None and keyfile is None:
        return None
    if certfile is None or keyfile is None:
        raise InputError("TLS needs both --certfile and --keyfile")
    import ssl

    from relaxgrip.fileio import check_input_file

    check_input_file(certfile, "--certfile file", InputError, max_bytes=1 << 20)
    check_input_file(keyfile, "--keyfile file", InputError, max_bytes=1 << 20)
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    try:
        # A passphrase would be asked on the terminal: refused instead of prompting.
        context.load_cert_chain(certfile, keyfile, password=lambda: b"")
    except (ssl.SSLError, OSError) as exc:
        reason = getattr(exc, "reason", None) or getattr(exc, "strerror", None) or exc
        raise InputError(f"--certfile {certfile} and --keyfile {keyfile} do not load as a "
                         f"TLS certificate and its key: {reason}") from None
    return certfile, keyfile


class _InvalidTextFilter(logging.Filter):
    """uvicorn's traceback for a client's text frame that is not UTF-8, as one line.

    uvicorn decodes a WebSocket text frame before the application sees it; on
    invalid UTF-8 it closes the connection with 1007 and logged the decoding's
    traceback as an error of the server's, for a client's bad byte.  That
    record becomes a warning naming the problem, without the traceback.  Only
    a ``UnicodeDecodeError`` raised in uvicorn's WebSocket protocol itself is
    changed: one raised in the application keeps its traceback.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        """Rewrite uvicorn's record of invalid UTF-8 from a client; keep every record."""
        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, UnicodeDecodeError) and exc.__traceback__ is not None:
            tb = exc.__traceback__
            while tb.tb_next is not None:
                tb = tb.tb_next
            if str(tb.tb_frame.f_globals.get("__name__", "")).startswith(
                    "uvicorn.protocols.websockets."):
                record.msg = ("a WebSocket client sent a text frame that is not UTF-8 (%s): "
                              "connection closed (1007)")
                record.args = (exc,)
                record.exc_info, record.exc_text = None, None
                record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


def _hangup_server(config: Any) -> Any:
    """A uvicorn server that a hang-up (a closed terminal) shuts down as SIGTERM does.

    uvicorn shuts down gracefully on SIGINT and SIGTERM, then raises them
    again for the command's own handlers (a stop with exit code 130).  A
    SIGHUP raised our ``KeyboardInterrupt`` inside its event loop instead,
    which printed the loop's tasks' tracebacks.  Ignored (``nohup``), it stays
    ignored.  A second Ctrl-C (uvicorn's force quit) still runs the application's
    shutdown (motor stopped, heaters off, recording closed), which uvicorn skips: the
    running lifespan was cancelled instead, and its traceback printed.
    """
    import uvicorn

    class HangupServer(uvicorn.Server):
        async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
            await super().shutdown(sockets)
            if self.force_exit:  # skipped by uvicorn: the connections were not waited for
                await self.lifespan.shutdown()

        @contextlib.contextmanager
        def capture_signals(self) -> Iterator[None]:
            with super().capture_signals():  # raises what it caught once restored
                hooked = (threading.current_thread() is threading.main_thread()
                          and signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN)
                previous = signal.signal(signal.SIGHUP, self.handle_exit) if hooked else None
                try:
                    yield
                finally:
                    if hooked:
                        signal.signal(signal.SIGHUP, previous)

    return HangupServer(config)


def _resolve(host: str, port: int) -> tuple[int, int, int, Any]:
    """Family, type, protocol and socket address of ``host:port`` (the first one found)."""
    try:
        family, kind, proto, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM)[0]
    except socket.gaierror as exc:
        raise InputError(f"--host {host}: cannot resolve it ({exc.strerror})") from None
    return family, kind, proto, address


def _bind(resolved: tuple[int, int, int, Any], host: str, port: int) -> socket.socket:
    """A TCP socket bound to the address :func:`_resolve` found (not yet listening)."""
    family, kind, proto, address = resolved
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
    except OSError as exc:
        sock.close()
        raise InputError(f"cannot serve on {host}:{port}: {exc.strerror}") from None
    return sock
