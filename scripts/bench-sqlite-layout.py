#!/usr/bin/env python3
"""The historian's SQLite layout at a million tags, in isolation (issue 34).

Python's sqlite3 on the historian's three tables as the migrations make them
(samples keyed by tag then time; the minute and hour roll-ups keyed by tag
then bucket; all WITHOUT ROWID), WAL and synchronous=NORMAL as the store
opens them. Each round logs one sample of every one of TAGS tags, in random
order, BATCH samples a transaction sorted by tag as the writer sorts them,
each with an upsert into both roll-up levels (or none: --samples-only).
Prints samples written a second. What it answers: how much of SQLite's time
at a million distinct tags goes to the roll-up trees, and what the page size
and the transaction size change. It is not the writer (no Rust, no
prepared statements of its own): compare its figures with each other.

    # grow a database (5 rounds), then 2 rounds with roll-ups, 2 without
    python3 scripts/bench-sqlite-layout.py --db /tmp/l4k.db --page-size 4096
    python3 scripts/bench-sqlite-layout.py --db /tmp/l1k.db --page-size 1024
    # the same, then the open-bucket design (minutes written as they close)
    python3 scripts/bench-sqlite-layout.py --db /tmp/l4k.db --rounds 3 --closed-minutes
    # one more round on a grown database, at another transaction size
    python3 scripts/bench-sqlite-layout.py --db /tmp/l4k.db --reuse --first-round 20 \\
        --rounds 1 --batch 5000 --rollups-only
"""
import argparse
import os
import random
import sqlite3
import time

ROLLUP = ("CREATE TABLE {t} (tag_id INTEGER NOT NULL, bucket INTEGER NOT NULL, n INTEGER NOT NULL, "
          "n_value INTEGER NOT NULL, min_value REAL, max_value REAL, sum_value REAL, "
          "first_ts INTEGER NOT NULL, first_value REAL, last_ts INTEGER NOT NULL, last_value REAL, "
          "last_quality INTEGER NOT NULL, bad_ms INTEGER NOT NULL, PRIMARY KEY (tag_id, bucket)) WITHOUT ROWID")
LEVELS = (("samples_minute", 60_000), ("samples_hour", 3_600_000))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--db", required=True)
    ap.add_argument("--page-size", type=int, default=4096)
    ap.add_argument("--tags", type=int, default=1_000_000)
    ap.add_argument("--batch", type=int, default=47_000, help="samples a transaction")
    ap.add_argument("--grow-rounds", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--reuse", action="store_true", help="go on with an existing database")
    ap.add_argument("--first-round", type=int, default=0, help="with --reuse: the rounds' time goes on from here")
    ap.add_argument("--rollups-only", action="store_true", help="measure with roll-ups only")
    ap.add_argument("--closed-minutes", action="store_true",
                    help="also measure the open-bucket design: each tag's minute written once when "
                         "the minute closes, and merged into its hour then (docs/research/million-tags.md, 13)")
    ap.add_argument("--closed-only", action="store_true",
                    help="with --reuse: measure the open-bucket design only")
    ap.add_argument("--cache-mib", type=int, default=0,
                    help="SQLite's page cache of the connection (0: its default, 2 MiB)")
    a = ap.parse_args()

    if not a.reuse:
        for suffix in ("", "-wal", "-shm"):
            if os.path.exists(a.db + suffix):
                os.remove(a.db + suffix)
    c = sqlite3.connect(a.db, isolation_level=None)
    if not a.reuse:
        c.execute(f"PRAGMA page_size={a.page_size}")
    c.execute("PRAGMA journal_mode=WAL")
    if a.cache_mib:
        c.execute(f"PRAGMA cache_size=-{a.cache_mib * 1024}")
    c.execute("PRAGMA synchronous=NORMAL")
    if not a.reuse:
        c.execute("CREATE TABLE samples (tag_id INTEGER NOT NULL, ts INTEGER NOT NULL, value REAL, "
                  "quality INTEGER NOT NULL, PRIMARY KEY (tag_id, ts)) WITHOUT ROWID")
        for table, _ in LEVELS:
            c.execute(ROLLUP.format(t=table))

    ids = list(range(a.tags))

    def run(first, last, rollups):
        """Rounds first..last; samples a second. A tag's samples are 21 s apart.
        rollups: True (each batch into both levels), False, or "closed" (the
        tags of a minute written once when it closes, and merged into the hour)."""
        n = 0
        started = time.time()
        open_minute, open_tags = None, set()
        for r in range(first, last):
            random.shuffle(ids)
            for i in range(0, a.tags, a.batch):
                batch = sorted(ids[i:i + a.batch])
                ts = r * 21_000 + i // a.batch
                c.execute("BEGIN")
                c.executemany("INSERT INTO samples VALUES (?, ?, ?, 0)", [(t, ts, 1.5) for t in batch])
                if rollups == "closed":
                    minute = ts - ts % 60_000
                    if open_minute is not None and minute != open_minute:
                        closed = sorted(open_tags)
                        c.executemany("INSERT INTO samples_minute VALUES (?, ?, 3, 3, ?, ?, ?, ?, ?, ?, ?, 0, 0)",
                                      [(t, open_minute, 1.5, 1.5, 4.5, open_minute, 1.5, open_minute, 1.5) for t in closed])
                        hour = open_minute - open_minute % 3_600_000
                        c.executemany(
                            "INSERT INTO samples_hour VALUES (?, ?, 3, 3, ?, ?, ?, ?, ?, ?, ?, 0, 0) "
                            "ON CONFLICT (tag_id, bucket) DO UPDATE SET n = n + 3, last_ts = excluded.last_ts",
                            [(t, hour, 1.5, 1.5, 4.5, open_minute, 1.5, open_minute, 1.5) for t in closed])
                        open_tags = set()
                    open_minute = minute
                    open_tags.update(batch)
                elif rollups:
                    for table, w in LEVELS:
                        bucket = ts - ts % w
                        c.executemany(
                            f"INSERT INTO {table} VALUES (?, ?, 1, 1, ?, ?, ?, ?, ?, ?, ?, 0, 0) "
                            "ON CONFLICT (tag_id, bucket) DO UPDATE SET n = n + 1, last_ts = excluded.last_ts",
                            [(t, bucket, 1.5, 1.5, 1.5, ts, 1.5, ts, 1.5) for t in batch])
                c.execute("COMMIT")
                n += len(batch)
        return n / (time.time() - started)

    first = a.first_round
    if not a.reuse:
        run(0, a.grow_rounds, True)
        first = a.grow_rounds
    page = c.execute("PRAGMA page_size").fetchone()[0]
    if a.closed_only:
        rate = run(first, first + a.rounds, "closed")
        print(f"page size {page}, cache {a.cache_mib or 2} MiB, {a.batch} samples a transaction, "
              f"minutes written as they close: {rate:,.0f} samples/s", flush=True)
        return
    rate = run(first, first + a.rounds, True)
    print(f"page size {page}, {a.batch} samples a transaction, with roll-ups: {rate:,.0f} samples/s", flush=True)
    if not a.rollups_only:
        rate = run(first + a.rounds, first + 2 * a.rounds, False)
        print(f"page size {page}, {a.batch} samples a transaction, samples only: {rate:,.0f} samples/s", flush=True)
    if a.closed_minutes:
        rate = run(first + 2 * a.rounds, first + 3 * a.rounds, "closed")
        print(f"page size {page}, {a.batch} samples a transaction, minutes written as they close: "
              f"{rate:,.0f} samples/s", flush=True)
    print(f"database {os.path.getsize(a.db) >> 20} MiB")


if __name__ == "__main__":
    main()
