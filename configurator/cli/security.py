"""Security commands: `keys generate` (Ed25519 signing keys) and `broker-config` (Mosquitto)."""

from __future__ import annotations

import argparse
import os
import secrets
import shutil
import subprocess
import sys
from pathlib import Path

from configurator.brokerconf import Listener, ServiceUsers, clashes, render_acl, render_conf
from configurator.diagnostics import format_text
from configurator.files import write_atomic
from configurator.signing import SigningKeyError, generate_keys
from configurator.wire import validate_prefix
from configurator.workspace import check

EXIT_OK, EXIT_FINDINGS, EXIT_TOOL = 0, 1, 2


def cmd_keys(args: argparse.Namespace) -> int:
    try:
        pair = generate_keys(args.out, force=args.force)
    except SigningKeyError as exc:
        print(f"robotconf: {exc}", file=sys.stderr)
        return EXIT_FINDINGS
    print(f"private key (reconciler only, mode 0600): {pair.private}")
    print(f"public key (give to every agent as public_key): {pair.public}")
    return EXIT_OK


def _password_for(secrets_dir: Path, user: str) -> str:
    """The user's password from its file, made (random, 0600) when there is none yet."""
    path = secrets_dir / f"{user}.password"
    if path.is_file():
        return path.read_text(encoding="utf-8").strip()
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


def cmd_broker_config(args: argparse.Namespace) -> int:
    try:
        prefix = validate_prefix(args.prefix)
    except ValueError as exc:
        print(f"robotconf: {exc}", file=sys.stderr)
        return EXIT_TOOL
    checked = check(args.repo, args.rev)
    if not checked.ok or checked.repo.fleet is None:
        sys.stderr.write(format_text(checked.errors))
        print("robotconf: broker-config needs a valid configs/fleet.yaml", file=sys.stderr)
        return EXIT_FINDINGS
    robots = sorted(checked.repo.fleet.model.robots)
    users = ServiceUsers(args.reconciler_user, args.viewer_user)
    clash = clashes(robots, users)
    if clash:
        print(
            f"robotconf: robot id(s) {', '.join(clash)} equal a service user name; "
            "rename the robot or pass --reconciler-user/--viewer-user",
            file=sys.stderr,
        )
        return EXIT_FINDINGS
    out: Path = args.out
    acl_file, conf_file = out / "acl", out / "mosquitto.conf"
    listener = Listener(
        port=args.port,
        bind=args.bind,
        certfile=args.certfile.resolve() if args.certfile else None,
        keyfile=args.keyfile.resolve() if args.keyfile else None,
        cafile=args.cafile.resolve() if args.cafile else None,
        require_certificate=args.require_certificate,
    )
    service_port = args.service_port or args.port + 1
    acl = render_acl(prefix, robots, users)
    # The broker host may keep the files elsewhere than where they are written now.
    conf = render_conf(listener, service_port, args.install_dir or out.resolve())
    # Robots and services in separate files: each listener knows only its own users.
    passwd = {out / "passwd": set(robots), out / "passwd-services": users.names()}

    if args.check:
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
        for line in stale:
            print(f"robotconf: {line}", file=sys.stderr)
        if stale:
            print("robotconf: run robotconf broker-config to update", file=sys.stderr)
            return EXIT_FINDINGS
        print(f"{out}: current for {len(robots)} robot(s)")
        return EXIT_OK

    tool = _mosquitto_passwd()
    if tool is None:
        print(
            "robotconf: mosquitto_passwd not found; install Debian's mosquitto package",
            file=sys.stderr,
        )
        return EXIT_TOOL
    secrets_dir: Path = args.secrets or out / "secrets"
    secrets_dir.mkdir(parents=True, exist_ok=True)
    os.chmod(secrets_dir, 0o700)
    out.mkdir(parents=True, exist_ok=True)
    for passwd_file, wanted in passwd.items():
        problem = _write_passwd(tool, passwd_file, wanted, secrets_dir)
        if problem is not None:
            print(f"robotconf: {problem}", file=sys.stderr)
            return EXIT_TOOL
    acl_file.write_text(acl, encoding="utf-8")
    conf_file.write_text(conf, encoding="utf-8")
    count = len(robots) + len(users.names())
    print(f"wrote {conf_file}, {acl_file}, {', '.join(str(p) for p in passwd)} ({count} users)")
    print(f"robots connect on port {args.port}, the reconciler and viewers on {service_port}")
    print(f"passwords: {secrets_dir}/<user>.password (0600); give each robot its own file")
    print("the broker reads passwd and acl: make them readable by its user (chown mosquitto)")
    return EXIT_OK


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
