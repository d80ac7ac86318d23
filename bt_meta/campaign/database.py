"""The campaign database, ``DIR/campaign.sqlite``: one row per finished episode, written only by the driver.

An episode is keyed by (variant, configuration, seed); a row is inserted in its own transaction once the episode
has finished, so a campaign killed at any moment (SIGKILL included) has lost only the episodes in flight, which
the same command runs again; a key already present is never inserted twice. The database remembers the campaign
version and the digest of the manifest it ran: a database of another version or another manifest is refused.

Offers:

* :class:`CampaignDatabase` -- ``open(folder, digest)``, ``done()``, ``add(row)``, ``rows()``, ``close()``
* :data:`DATABASE` -- the file name
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

from bt_meta.campaign import CAMPAIGN_VERSION
from bt_meta.campaign.manifest import CampaignDirError

__all__ = ["DATABASE", "CampaignDatabase"]

DATABASE = "campaign.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS episodes (
    variant TEXT NOT NULL, configuration TEXT NOT NULL, seed INTEGER NOT NULL,
    expected TEXT NOT NULL, status TEXT NOT NULL, success INTEGER NOT NULL, attempts INTEGER NOT NULL,
    seconds REAL NOT NULL, result TEXT NOT NULL,
    PRIMARY KEY (variant, configuration, seed)
);
"""


class CampaignDatabase:
    def __init__(self, connection: sqlite3.Connection, path: Path) -> None:
        self._connection = connection
        self.path = path

    @classmethod
    def open(cls, folder: str | Path, digest: str, *, create: bool = True) -> CampaignDatabase:
        path = Path(folder) / DATABASE
        if not create and not path.is_file():
            raise CampaignDirError("no episodes yet: run `bt-meta campaign run` first", path)
        try:
            connection = sqlite3.connect(path, isolation_level=None)
            connection.execute("PRAGMA journal_mode=WAL")
            connection.executescript(_SCHEMA)
            meta = dict(connection.execute("SELECT key, value FROM meta").fetchall())
        except sqlite3.DatabaseError as error:
            raise CampaignDirError(f"not a campaign database ({error})", path) from None
        if not meta:
            connection.execute("BEGIN")
            connection.executemany("INSERT INTO meta VALUES (?, ?)",
                                   [("campaign_version", str(CAMPAIGN_VERSION)), ("manifest", digest)])
            connection.execute("COMMIT")
        elif meta.get("campaign_version") != str(CAMPAIGN_VERSION):
            connection.close()
            raise CampaignDirError(f"written by another version of bt-meta (campaign version "
                                   f"{meta.get('campaign_version')}, this one writes {CAMPAIGN_VERSION}); remove it "
                                   "to start again", path)
        elif meta.get("manifest") != digest:
            connection.close()
            raise CampaignDirError("its episodes ran another campaign.json (the manifest changed since): remove "
                                   "the database to start again, never mixed", path)
        return cls(connection, path)

    def close(self) -> None:
        self._connection.close()

    def __enter__(self) -> CampaignDatabase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def check_sensing(self, sensing: str) -> None:
        """The first run fixes the campaign's sensing (``perceived`` or ``perfect``); another is refused."""
        row = self._connection.execute("SELECT value FROM meta WHERE key = 'sensing'").fetchone()
        if row is None:
            self._connection.execute("INSERT INTO meta VALUES ('sensing', ?)", (sensing,))
        elif row[0] != sensing:
            option = "--perfect-sensing" if row[0] == "perfect" else "no --perfect-sensing"
            raise CampaignDirError(f"its episodes ran with {row[0]} sensing, this run asks for {sensing}: never "
                                   f"mixed; use {option} or another campaign directory", self.path)

    def done(self) -> set[tuple[str, str, int]]:
        return {(v, c, int(s)) for v, c, s in
                self._connection.execute("SELECT variant, configuration, seed FROM episodes")}

    def add(self, row: dict[str, Any]) -> bool:
        """Insert a finished episode; False (and nothing written) when its key is already there."""
        cursor = self._connection.execute(
            "INSERT OR IGNORE INTO episodes VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (row["variant"], row["configuration"], int(row["seed"]), row["expected"], row["status"],
             int(bool(row["success"])), int(row["attempts"]), float(row["seconds"]), json.dumps(row, default=str)))
        return cursor.rowcount == 1

    def rows(self) -> list[dict[str, Any]]:
        return [json.loads(text) for (text,) in self._connection.execute(
            "SELECT result FROM episodes ORDER BY variant, configuration, seed")]
