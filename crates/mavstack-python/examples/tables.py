"""A log as tables: ATTITUDE and GLOBAL_POSITION_INT from `mavstack.read_tlog` into polars,
a summary of each.

    python tables.py flight.tlog

Typed: `mypy --strict` and pyright (strict) pass on it.
"""

import sys

import polars as pl

import mavstack


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    tables = mavstack.read_tlog(sys.argv[1], types=["ATTITUDE", "GLOBAL_POSITION_INT"])
    for name, table in tables.items():
        print("%s: %d rows" % (name, table.num_rows))
    if "ATTITUDE" in tables:
        att = pl.DataFrame(tables["ATTITUDE"])
        t0 = att["timestamp_us"][0]
        att = att.with_columns(((pl.col("timestamp_us") - t0) / 1e6).alias("t"))
        print(att.select("t", "roll", "pitch", "yaw").describe())
    if "GLOBAL_POSITION_INT" in tables:
        pos = pl.DataFrame(tables["GLOBAL_POSITION_INT"])
        print(pos.group_by("sysid").agg(pl.len().alias("fixes"),
                                        (pl.col("relative_alt").max() / 1000).alias("max_alt_m")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
