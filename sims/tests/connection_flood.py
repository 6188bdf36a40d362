"""An unauthenticated connection flood for sims/tests/security_processes.rs.

Opens RATE connections per second to each PORT on 127.0.0.1 for SECONDS seconds,
taking turns between three kinds, as a stranger without the team's credentials
would:
- junk: 517 random bytes where a TLS ClientHello belongs, then close;
- tls: a real TLS 1.3 handshake by Python's `ssl` (trusting the team's CA when
  --ca is given) without a client certificate, which a mutual-TLS listener refuses;
- idle: connect and send nothing, holding the socket for --idle-s seconds.
Prints one JSON line: connections opened per kind and how many the listener refused
at connect time.
"""

import argparse
import asyncio
import json
import os
import ssl

KINDS = ("junk", "tls", "idle")


async def one(port, kind, args, context, counts, held):
    try:
        if kind == "tls":
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection("127.0.0.1", port, ssl=context, server_hostname="robot"),
                timeout=5,
            )
        else:
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection("127.0.0.1", port), timeout=5
            )
    except (OSError, ssl.SSLError, asyncio.TimeoutError):
        counts["refused"] += 1
        return
    counts[kind] += 1
    try:
        if kind == "junk":
            writer.write(os.urandom(517))
            await writer.drain()
        elif kind == "tls":
            # The listener refuses a client without a certificate after the handshake.
            await asyncio.wait_for(reader.read(1), timeout=5)
        else:
            held.append(writer)
            await asyncio.sleep(args.idle_s)
    except (OSError, ssl.SSLError, asyncio.TimeoutError):
        pass
    finally:
        writer.close()


async def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("ports", type=int, nargs="+")
    ap.add_argument("--rate", type=float, default=30.0, help="connections per second per port")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--idle-s", type=float, default=15.0)
    ap.add_argument("--ca", help="the team's CA, so the TLS kind fails only for want of a certificate")
    args = ap.parse_args()

    context = ssl.create_default_context(cafile=args.ca) if args.ca else ssl._create_unverified_context()
    context.check_hostname = False
    if not args.ca:
        context.verify_mode = ssl.CERT_NONE
    counts = {k: 0 for k in KINDS} | {"refused": 0}
    held = []
    tasks = []
    loop = asyncio.get_running_loop()
    start = loop.time()
    n = 0
    while loop.time() - start < args.seconds:
        for port in args.ports:
            tasks.append(asyncio.create_task(one(port, KINDS[n % 3], args, context, counts, held)))
        n += 1
        await asyncio.sleep(max(0.0, start + n / args.rate - loop.time()))
    await asyncio.gather(*tasks, return_exceptions=True)
    print(json.dumps(counts), flush=True)


if __name__ == "__main__":
    asyncio.run(main())
