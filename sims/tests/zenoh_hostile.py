"""A hostile zenoh client (eclipse-zenoh from PyPI) for sims/tests/transport/security.rs.

Connects in client mode to ENDPOINT with the credentials given (none, TLS files,
user/password), then puts PAYLOAD_FILE's bytes COUNT times on each KEY (and each
--put-file KEY=FILE[=ATTACHMENT]'s bytes on its key, with ATTACHMENT's bytes as
the zenoh attachment: a frame signature), 20 ms apart (and --gap-ms apart within a
round); or (with --size-mb) one payload of that many megabytes; or (with --flood N)
N copies of PAYLOAD_FILE on the first KEY as fast as zenoh takes them. Prints one JSON line: whether the
session opened, and how many puts zenoh accepted locally.
"""

import argparse
import json
import sys
import time

import zenoh


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("endpoint")
    ap.add_argument("--ca")
    ap.add_argument("--cert")
    ap.add_argument("--key")
    ap.add_argument("--user")
    ap.add_argument("--password")
    ap.add_argument("--put", action="append", default=[], metavar="KEY")
    ap.add_argument("--payload-file")
    ap.add_argument("--count", type=int, default=50)
    ap.add_argument("--size-mb", type=int)
    ap.add_argument("--put-file", action="append", default=[], metavar="KEY=FILE[=ATTACHMENT]")
    ap.add_argument("--flood", type=int)
    ap.add_argument("--gap-ms", type=float, default=0.0)
    a = ap.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([a.endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if a.ca:
        tls = "transport/link/tls/"
        conf.insert_json5(tls + "root_ca_certificate", json.dumps(a.ca))
        conf.insert_json5(tls + "verify_name_on_connect", "false")
        if a.cert:
            conf.insert_json5(tls + "enable_mtls", "true")
            conf.insert_json5(tls + "connect_certificate", json.dumps(a.cert))
            conf.insert_json5(tls + "connect_private_key", json.dumps(a.key))
    if a.user:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(a.user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(a.password))
    try:
        session = zenoh.open(conf)
    except Exception as e:  # refused: no session, nothing to inject
        print(json.dumps({"opened": False, "error": str(e)[:200], "puts": 0}))
        return 0
    puts = 0
    block = zenoh.CongestionControl.BLOCK
    if a.size_mb:
        key = a.put[0]
        # Blocking, so that no fragment is dropped on the way: the robot gets it all.
        session.put(key, bytes(a.size_mb * 1_000_000), congestion_control=block)
        puts += 1
        time.sleep(2.0)
    elif a.flood:
        payload = open(a.payload_file, "rb").read()
        for _ in range(a.flood):
            session.put(a.put[0], payload, congestion_control=block)
            puts += 1
        time.sleep(0.5)
    else:
        payload = open(a.payload_file, "rb").read() if a.payload_file else b""
        frames = [(key, payload, None) for key in a.put]
        for spec in a.put_file:
            key, path, *attachment = spec.split("=", 2)
            attachment = open(attachment[0], "rb").read() if attachment else None
            frames.append((key, open(path, "rb").read(), attachment))
        for _ in range(a.count):
            for key, body, attachment in frames:
                session.put(key, body, congestion_control=block, attachment=attachment)
                puts += 1
                time.sleep(a.gap_ms / 1000)
            time.sleep(0.02)
        time.sleep(0.5)
    session.close()
    print(json.dumps({"opened": True, "puts": puts}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
