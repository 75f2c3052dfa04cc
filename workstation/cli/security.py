"""Security commands: `keys generate` (Ed25519 signing keys) and `broker-config` (Mosquitto)."""

from __future__ import annotations

import os
import secrets
import shutil
import subprocess
import sys
from pathlib import Path

import click

from robotconf.configurator.brokerconf import (
    Listener,
    ServiceUsers,
    clashes,
    render_acl,
    render_conf,
)
from robotconf.configurator.workspace import check
from robotconf.contract.diagnostics import format_text
from robotconf.contract.errors import CliError, ExitCode
from robotconf.contract.files import write_atomic
from robotconf.contract.models import file_name
from robotconf.contract.signing import SigningKeyError, generate_keys
from robotconf.contract.trust import UntrustedFile, read_secret_text
from robotconf.contract.wire import DEFAULT_PREFIX, validate_prefix
from robotconf.workstation.cli.options import repo_option, rev_option


@click.command("keys")
@click.argument("action", type=click.Choice(["generate"]), metavar="ACTION")
@click.option(
    "--out", type=click.Path(path_type=Path), default=Path("keys"), help="folder (default: keys/)"
)
@click.option("--force", is_flag=True, help="replace an existing pair")
def keys(action: str, out: Path, force: bool) -> ExitCode:
    """Make the Ed25519 key pair that signs Launch Requests (ACTION: generate)."""
    try:
        pair = generate_keys(out, force=force)
    except SigningKeyError as exc:
        raise CliError(str(exc), ExitCode.FINDINGS) from None
    print(f"private key (reconciler only, mode 0600): {pair.private}")
    print(f"public key (give to every agent as public_key): {pair.public}")
    return ExitCode.OK


def _password_for(secrets_dir: Path, user: str) -> str:
    """The user's password from its file, made (random, 0600) when there is none yet."""
    path = secrets_dir / f"{user}.password"
    if path.is_file():
        try:
            return read_secret_text(path)
        except UntrustedFile as exc:
            raise CliError(f"password file {path} {exc}") from None
    password = secrets.token_urlsafe(24)
    write_atomic(path, (password + "\n").encode("utf-8"), 0o600)
    return password


def _passwd_users(path: Path) -> set[str]:
    if not path.is_file():
        return set()
    lines = path.read_text(encoding="utf-8").splitlines()
    return {line.split(":", 1)[0] for line in lines if ":" in line and not line.startswith("#")}


def _mosquitto_passwd() -> str | None:
    return shutil.which("mosquitto_passwd") or (
        "/usr/bin/mosquitto_passwd" if Path("/usr/bin/mosquitto_passwd").exists() else None
    )


_PATH = click.Path(path_type=Path)


@click.command("broker-config")
@repo_option
@rev_option
@click.option("--prefix", default=DEFAULT_PREFIX, help=f"topic prefix (default: {DEFAULT_PREFIX})")
@click.option("--out", type=_PATH, default=Path("broker"), help="folder (default: broker/)")
@click.option(
    "--install-dir",
    type=_PATH,
    default=None,
    help="where the broker host keeps acl and passwd (default: OUT)",
)
@click.option("--secrets", type=_PATH, default=None, help="password files (default: OUT/secrets)")
@click.option("--port", type=int, default=8883, help="robots' listener port (default: 8883)")
@click.option(
    "--service-port",
    type=int,
    default=None,
    help="listener port of the reconciler and viewers (default: --port + 1)",
)
@click.option("--bind", default=None, help="listener address (default: all)")
@click.option("--certfile", type=_PATH, default=None, help="server certificate (TLS)")
@click.option("--keyfile", type=_PATH, default=None, help="server key (TLS)")
@click.option("--cafile", type=_PATH, default=None, help="CA for client certificates")
@click.option("--require-certificate", is_flag=True, help="clients must present one")
@click.option("--reconciler-user", default="reconciler")
@click.option("--viewer-user", default="viewer", help="reads the fleet's topics, writes nothing")
@click.option(
    "--operator-user",
    default="operator",
    help="reads everything and the robots' logs; asks for logs and restarts",
)
@click.option("--check", "check_only", is_flag=True, help="fail when the files are stale")
def broker_config(
    repo: Path,
    rev: str | None,
    prefix: str,
    out: Path,
    install_dir: Path | None,
    secrets: Path | None,
    port: int,
    service_port: int | None,
    bind: str | None,
    certfile: Path | None,
    keyfile: Path | None,
    cafile: Path | None,
    require_certificate: bool,
    reconciler_user: str,
    viewer_user: str,
    operator_user: str,
    check_only: bool,
) -> ExitCode:
    """Write Mosquitto ACL, password files and TLS listeners from configs/fleet.yaml."""
    try:
        prefix = validate_prefix(prefix)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    users = ServiceUsers(  # each names its password file and an ACL line
        file_name("--reconciler-user", reconciler_user),
        file_name("--viewer-user", viewer_user),
        file_name("--operator-user", operator_user),
    )
    robots = _fleet_robots(repo, rev, users)
    listener = Listener(
        port=port,
        bind=bind,
        certfile=certfile.resolve() if certfile else None,
        keyfile=keyfile.resolve() if keyfile else None,
        cafile=cafile.resolve() if cafile else None,
        require_certificate=require_certificate,
    )
    service_port = service_port or port + 1
    acl = render_acl(prefix, robots, users)
    # The broker host may keep the files elsewhere than where they are written now.
    conf = render_conf(listener, service_port, install_dir or out.resolve(), len(robots))
    # Robots and services in separate files: each listener knows only its own users.
    passwd = {out / "passwd": set(robots), out / "passwd-services": users.names()}
    if check_only:
        return _check_current(out, acl, passwd, len(robots))
    secrets_dir = secrets or out / "secrets"
    _write_all(out, secrets_dir, acl, conf, passwd)
    print(f"robots connect on port {port}; the reconciler, viewers and operators on {service_port}")
    print(f"passwords: {secrets_dir}/<user>.password (0600); give each robot its own file")
    print("the broker reads passwd and acl: make them readable by its user (chown mosquitto)")
    return ExitCode.OK


def _fleet_robots(repo: Path, rev: str | None, users: ServiceUsers) -> list[str]:
    """The fleet's robot ids, once the repository validates and none is a service user."""
    checked = check(repo, rev)
    if not checked.ok or checked.repo.fleet is None:
        sys.stderr.write(format_text(checked.errors))
        raise CliError("broker-config needs a valid configs/fleet.yaml", ExitCode.FINDINGS)
    robots = sorted(checked.repo.fleet.model.robots)
    if len(users.names()) < 3:
        raise CliError(
            "--reconciler-user, --viewer-user and --operator-user must be three different names"
        )
    clash = clashes(robots, users)
    if clash:
        raise CliError(
            f"robot id(s) {', '.join(clash)} equal a service user name; "
            "rename the robot or pass --reconciler-user/--viewer-user/--operator-user",
            ExitCode.FINDINGS,
        )
    return robots


def _check_current(out: Path, acl: str, passwd: dict[Path, set[str]], robots: int) -> ExitCode:
    """--check: the written ACL and password files against what the fleet asks for."""
    acl_file = out / "acl"
    stale = []
    if not acl_file.is_file() or acl_file.read_text(encoding="utf-8") != acl:
        stale.append(f"{acl_file} differs from the fleet")
    for passwd_file, wanted in passwd.items():
        have = _passwd_users(passwd_file)
        if have != wanted:
            missing, extra = sorted(wanted - have), sorted(have - wanted)
            stale.append(
                f"{passwd_file}: missing {', '.join(missing) or '-'}; "
                f"extra {', '.join(extra) or '-'}"
            )
    if stale:
        raise CliError(
            "\nrobotconf: ".join([*stale, "run robotconf broker-config to update"]),
            ExitCode.FINDINGS,
        )
    print(f"{out}: current for {robots} robot(s)")
    return ExitCode.OK


def _write_all(
    out: Path, secrets_dir: Path, acl: str, conf: str, passwd: dict[Path, set[str]]
) -> None:
    """The password files (hashed by mosquitto_passwd), the ACL and mosquitto.conf."""
    tool = _mosquitto_passwd()
    if tool is None:
        raise CliError("mosquitto_passwd not found; install Debian's mosquitto package")
    secrets_dir.mkdir(parents=True, exist_ok=True)
    os.chmod(secrets_dir, 0o700)
    out.mkdir(parents=True, exist_ok=True)
    for passwd_file, wanted in passwd.items():
        problem = _write_passwd(tool, passwd_file, wanted, secrets_dir)
        if problem is not None:
            raise CliError(problem)
    acl_file, conf_file = out / "acl", out / "mosquitto.conf"
    acl_file.write_text(acl, encoding="utf-8")
    conf_file.write_text(conf, encoding="utf-8")
    count = sum(len(users) for users in passwd.values())
    print(f"wrote {conf_file}, {acl_file}, {', '.join(str(p) for p in passwd)} ({count} users)")


def _write_passwd(tool: str, passwd_file: Path, users: set[str], secrets_dir: Path) -> str | None:
    """Plain entries go to a 0600 file that mosquitto_passwd hashes in place: no password ever
    appears on a command line or in a log. None when written, else why not."""
    plain = "".join(f"{u}:{_password_for(secrets_dir, u)}\n" for u in sorted(users))
    staging = passwd_file.with_name(f".{passwd_file.name}.staging")
    write_atomic(staging, plain.encode("utf-8"), 0o600)
    done = subprocess.run([tool, "-U", str(staging)], capture_output=True, text=True)
    if done.returncode != 0:
        staging.unlink(missing_ok=True)
        return f"mosquitto_passwd failed: {done.stderr.strip()}"
    os.replace(staging, passwd_file)
    return None
