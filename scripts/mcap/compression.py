#!/usr/bin/env python3
"""Compares MCAP chunk compressions on a troupe recording (one written with any
`record_compression`): rewrites it with zstd and with lz4 chunks of 1 MiB (troupe's
chunk size) into /tmp and prints the sizes. Needs the Python `mcap`, `zstandard` and
`lz4` packages (`.venv-mcap` has them).

Usage: compression.py RUN.mcap
"""
import os
import sys
import time

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

src = sys.argv[1]
for kind in (CompressionType.ZSTD, CompressionType.LZ4):
    out = f"/tmp/rec21_{kind.name.lower()}.mcap"
    t0 = time.time()
    with open(src, "rb") as f, open(out, "wb") as g:
        w = Writer(g, chunk_size=1 << 20, compression=kind)
        w.start(profile="troupe", library="recompress")
        schemas, channels = {}, {}
        for schema, channel, message in make_reader(f).iter_messages():
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding, schemas[schema.id])
            w.add_message(channels[channel.id], message.log_time, message.data, message.publish_time, message.sequence)
        w.finish()
    print(kind.name, os.path.getsize(src), os.path.getsize(out), f"{os.path.getsize(out)/os.path.getsize(src):.3f}", f"{time.time()-t0:.1f} s")
