"""Reading a world directory from Python, without Horizon: its SQLite database (world.db, with
Python's own sqlite3 module) and its content-addressed blobs (blobs/ab/<hash>)."""
import json
import pathlib
import sqlite3


def query(world, sql, *args):
    db = sqlite3.connect(f"file:{pathlib.Path(world) / 'world.db'}?mode=ro", uri=True)
    try:
        return db.execute(sql, args).fetchall()
    finally:
        db.close()


def key(world, name):
    """A value of the world's key-value table (name, seed, generation, published, ...)."""
    rows = query(world, "SELECT value FROM world WHERE key = ?", name)
    return rows[0][0] if rows else None


def name(world):
    return key(world, "name")


def blob(world, hash_):
    return pathlib.Path(world) / "blobs" / hash_[:2] / hash_


def published_manifest(world):
    """The aggregate manifest the world publishes, or None before the first build."""
    published = key(world, "published")
    manifest = json.loads(published).get("manifest") if published else None
    return json.loads(blob(world, manifest).read_bytes()) if manifest else None
