//! [`SqliteMeta`]: the embedded [`MetaStore`], one SQLite database (`world.db`) in WAL mode
//! with full synchronisation, so a committed transaction survives a killed process and a
//! lost machine alike. One connection, behind a mutex: every call is one short transaction.
//! Object ids are never reused (`AUTOINCREMENT`): an id names one object for the world's life.

use std::path::Path;
use std::sync::{Mutex, MutexGuard};

use glam::Affine3A;
use rusqlite::{params, Connection, OptionalExtension, Transaction};

use super::{
    Applied, MetaStore, ModelDescriptors, ModelLevel, ModelRow, Mutation, NewModel, ObjectRow,
    Published, Snapshot, User,
};
use crate::error::WorldError;

/// The version of the schema below; part of the database, checked on open.
const SCHEMA: i64 = 1;

const CREATE: &str = "
CREATE TABLE IF NOT EXISTS world (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS models (
    number INTEGER PRIMARY KEY,
    id TEXT NOT NULL UNIQUE,
    asset TEXT NOT NULL,
    name TEXT NOT NULL,
    owner TEXT,
    bytes INTEGER NOT NULL,
    stats TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS models_owner ON models(owner);
CREATE TABLE IF NOT EXISTS descriptors (
    asset TEXT PRIMARY KEY,
    zernike BLOB NOT NULL,
    csd BLOB NOT NULL,
    centre BLOB NOT NULL,
    radius REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS levels (asset TEXT PRIMARY KEY, levels TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS objects (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    model INTEGER NOT NULL REFERENCES models(number),
    transform BLOB NOT NULL,
    owner TEXT,
    generation INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS objects_owner ON objects(owner, id);
CREATE TABLE IF NOT EXISTS users (
    name TEXT PRIMARY KEY,
    max_objects INTEGER,
    max_bytes INTEGER
);
CREATE TABLE IF NOT EXISTS tokens (
    hash TEXT PRIMARY KEY,
    user TEXT NOT NULL REFERENCES users(name)
);
CREATE TABLE IF NOT EXISTS log (
    generation INTEGER PRIMARY KEY,
    object INTEGER NOT NULL,
    model INTEGER,
    transform BLOB
);
CREATE TABLE IF NOT EXISTS aggregates (key TEXT PRIMARY KEY, entry TEXT NOT NULL);
";

/// The metadata of one world in SQLite (see the module docs).
#[derive(Debug)]
pub struct SqliteMeta {
    db: Mutex<Connection>,
}

impl SqliteMeta {
    /// Opens (creating if need be) the database at `path`. A new database records `name` and
    /// `seed` as the world's identity.
    pub fn open(path: &Path, name: &str, seed: u64) -> Result<Self, WorldError> {
        let db = Connection::open(path).map_err(|e| sql_at(path, e))?;
        db.pragma_update(None, "journal_mode", "WAL")
            .map_err(|e| sql_at(path, e))?;
        db.pragma_update(None, "synchronous", "FULL")
            .map_err(|e| sql_at(path, e))?;
        db.pragma_update(None, "foreign_keys", "ON")
            .map_err(|e| sql_at(path, e))?;
        db.busy_timeout(std::time::Duration::from_secs(10))
            .map_err(|e| sql_at(path, e))?;
        db.execute_batch(CREATE).map_err(|e| sql_at(path, e))?;
        let meta = Self { db: Mutex::new(db) };
        {
            let mut db = meta.lock()?;
            let tx = db.transaction().map_err(sql)?;
            match get_key(&tx, "schema")? {
                None => {
                    set_key(&tx, "schema", &SCHEMA.to_string())?;
                    set_key(&tx, "name", name)?;
                    set_key(&tx, "seed", &seed.to_string())?;
                    set_key(&tx, "generation", "0")?;
                }
                Some(v) if v == SCHEMA.to_string() => {}
                Some(v) => {
                    return Err(WorldError::Corrupt {
                        path: path.to_path_buf(),
                        reason: format!("schema {v} is not supported (expected {SCHEMA})"),
                    })
                }
            }
            tx.commit().map_err(sql)?;
        }
        Ok(meta)
    }

    /// Moves everything from the write-ahead log into the database file, so that the file
    /// alone holds the world (before it is renamed into place).
    pub fn checkpoint(&self) -> Result<(), WorldError> {
        let db = self.lock()?;
        db.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
            .map_err(sql)
    }

    fn lock(&self) -> Result<MutexGuard<'_, Connection>, WorldError> {
        self.db
            .lock()
            .map_err(|_| WorldError::Inconsistent("database lock poisoned".into()))
    }
}

impl MetaStore for SqliteMeta {
    fn identity(&self) -> Result<(String, u64), WorldError> {
        let db = self.lock()?;
        let name = get_key(&db, "name")?.unwrap_or_default();
        let seed = get_key(&db, "seed")?
            .and_then(|s| s.parse().ok())
            .unwrap_or(0);
        Ok((name, seed))
    }

    fn generation(&self) -> Result<u64, WorldError> {
        let db = self.lock()?;
        get_u64(&db, "generation")
    }

    fn add_model(&self, m: NewModel<'_>) -> Result<(ModelRow, bool), WorldError> {
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        if let Some(row) = model_by_id(&tx, m.id)? {
            return Ok((row, false));
        }
        if let Some(owner) = m.owner {
            check_bytes_quota(&tx, owner, m.bytes)?;
        }
        let number: i64 = tx
            .query_row("SELECT COUNT(*) FROM models", [], |r| r.get(0))
            .map_err(sql)?;
        tx.execute(
            "INSERT INTO models (number, id, asset, name, owner, bytes, stats)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            params![
                number,
                m.id,
                m.asset,
                m.name,
                m.owner,
                m.bytes as i64,
                m.stats.to_string()
            ],
        )
        .map_err(sql)?;
        if let Some(d) = m.descriptors {
            insert_descriptors(&tx, m.asset, d)?;
        }
        if let Some(levels) = m.levels {
            insert_levels(&tx, m.asset, levels)?;
        }
        let row = model_by_id(&tx, m.id)?
            .ok_or_else(|| WorldError::Inconsistent("a model vanished on insert".into()))?;
        tx.commit().map_err(sql)?;
        Ok((row, true))
    }

    fn check_model_quota(&self, owner: &str, bytes: u64) -> Result<(), WorldError> {
        let db = self.lock()?;
        check_bytes_quota(&db, owner, bytes)
    }

    fn model(&self, id: &str) -> Result<Option<ModelRow>, WorldError> {
        let db = self.lock()?;
        model_by_id(&db, id)
    }

    fn models(&self) -> Result<Vec<ModelRow>, WorldError> {
        let db = self.lock()?;
        let mut stmt = db
            .prepare(&format!("{MODEL_SELECT} ORDER BY number"))
            .map_err(sql)?;
        let rows = stmt.query_map([], model_row).map_err(sql)?;
        rows.map(|r| r.map_err(sql).and_then(finish_model))
            .collect()
    }

    fn models_page(&self, after: Option<&str>, limit: usize) -> Result<Vec<ModelRow>, WorldError> {
        let db = self.lock()?;
        let mut stmt = db
            .prepare(&format!(
                "{MODEL_SELECT} WHERE id > ?1 ORDER BY id LIMIT ?2"
            ))
            .map_err(sql)?;
        let rows = stmt
            .query_map(params![after.unwrap_or(""), limit as i64], model_row)
            .map_err(sql)?;
        rows.map(|r| r.map_err(sql).and_then(finish_model))
            .collect()
    }

    fn model_count(&self) -> Result<u64, WorldError> {
        let db = self.lock()?;
        count(&db, "SELECT COUNT(*) FROM models")
    }

    fn descriptors(&self, asset: &str) -> Result<Option<ModelDescriptors>, WorldError> {
        let db = self.lock()?;
        db.query_row(
            "SELECT zernike, csd, centre, radius FROM descriptors WHERE asset = ?1",
            [asset],
            |r| {
                let zernike: Vec<u8> = r.get(0)?;
                let csd: Vec<u8> = r.get(1)?;
                let centre: Vec<u8> = r.get(2)?;
                let radius: f64 = r.get(3)?;
                Ok((zernike, csd, centre, radius))
            },
        )
        .optional()
        .map_err(sql)?
        .map(|(zernike, csd, centre, radius)| {
            let centre = floats(&centre);
            if centre.len() != 3 {
                return Err(WorldError::Inconsistent(format!(
                    "descriptors of {asset} have a centre of {} values",
                    centre.len()
                )));
            }
            Ok(ModelDescriptors {
                zernike: floats(&zernike),
                csd: floats(&csd),
                centre: [centre[0], centre[1], centre[2]],
                radius: radius as f32,
            })
        })
        .transpose()
    }

    fn put_descriptors(&self, asset: &str, d: &ModelDescriptors) -> Result<(), WorldError> {
        let db = self.lock()?;
        insert_descriptors(&db, asset, d)
    }

    fn levels(&self, asset: &str) -> Result<Option<Vec<ModelLevel>>, WorldError> {
        let db = self.lock()?;
        let text: Option<String> = db
            .query_row("SELECT levels FROM levels WHERE asset = ?1", [asset], |r| {
                r.get(0)
            })
            .optional()
            .map_err(sql)?;
        text.map(|t| parse_levels(asset, &t)).transpose()
    }

    fn all_levels(&self) -> Result<std::collections::HashMap<String, Vec<ModelLevel>>, WorldError> {
        let db = self.lock()?;
        let mut stmt = db
            .prepare("SELECT asset, levels FROM levels")
            .map_err(sql)?;
        let rows = stmt
            .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?)))
            .map_err(sql)?;
        let mut out = std::collections::HashMap::new();
        for row in rows {
            let (asset, text) = row.map_err(sql)?;
            let levels = parse_levels(&asset, &text)?;
            out.insert(asset, levels);
        }
        Ok(out)
    }

    fn put_levels(&self, asset: &str, levels: &[ModelLevel]) -> Result<(), WorldError> {
        let db = self.lock()?;
        insert_levels(&db, asset, levels)
    }

    fn put_levels_batch(&self, rows: &[(String, Vec<ModelLevel>)]) -> Result<(), WorldError> {
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        for (asset, levels) in rows {
            insert_levels(&tx, asset, levels)?;
        }
        tx.commit().map_err(sql)
    }

    fn apply(
        &self,
        user: Option<&str>,
        mutations: &[Mutation],
    ) -> Result<Vec<Applied>, WorldError> {
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        let mut generation = get_u64(&tx, "generation")?;
        let mut applied = Vec::with_capacity(mutations.len());
        for m in mutations {
            generation += 1;
            let record = match *m {
                Mutation::Create { model, transform } => {
                    let known: Option<i64> = tx
                        .query_row(
                            "SELECT number FROM models WHERE number = ?1",
                            [model as i64],
                            |r| r.get(0),
                        )
                        .optional()
                        .map_err(sql)?;
                    if known.is_none() {
                        return Err(WorldError::UnknownModel(format!(
                            "no model numbered {model}"
                        )));
                    }
                    if let Some(user) = user {
                        check_object_quota(&tx, user)?;
                    }
                    tx.execute(
                        "INSERT INTO objects (model, transform, owner, generation)
                         VALUES (?1, ?2, ?3, ?4)",
                        params![
                            model as i64,
                            transform_bytes(&transform),
                            user,
                            generation as i64
                        ],
                    )
                    .map_err(sql)?;
                    Applied {
                        generation,
                        object: tx.last_insert_rowid() as u64,
                        state: Some((model, transform)),
                    }
                }
                Mutation::Move { id, transform } => {
                    let row = owned_object(&tx, id, user)?;
                    tx.execute(
                        "UPDATE objects SET transform = ?1, generation = ?2 WHERE id = ?3",
                        params![transform_bytes(&transform), generation as i64, id as i64],
                    )
                    .map_err(sql)?;
                    Applied {
                        generation,
                        object: id,
                        state: Some((row.model, transform)),
                    }
                }
                Mutation::Delete { id } => {
                    owned_object(&tx, id, user)?;
                    tx.execute("DELETE FROM objects WHERE id = ?1", [id as i64])
                        .map_err(sql)?;
                    Applied {
                        generation,
                        object: id,
                        state: None,
                    }
                }
            };
            let (model, transform) = match record.state {
                Some((model, t)) => (Some(model as i64), Some(transform_bytes(&t))),
                None => (None, None),
            };
            tx.execute(
                "INSERT INTO log (generation, object, model, transform) VALUES (?1, ?2, ?3, ?4)",
                params![generation as i64, record.object as i64, model, transform],
            )
            .map_err(sql)?;
            applied.push(record);
        }
        set_key(&tx, "generation", &generation.to_string())?;
        tx.commit().map_err(sql)?;
        Ok(applied)
    }

    fn object(&self, id: u64) -> Result<Option<ObjectRow>, WorldError> {
        let db = self.lock()?;
        object_by_id(&db, id)
    }

    fn objects_page(
        &self,
        after: Option<u64>,
        limit: usize,
        owner: Option<&str>,
    ) -> Result<Vec<ObjectRow>, WorldError> {
        let db = self.lock()?;
        let after = after.map_or(-1, |a| a as i64);
        let rows = match owner {
            Some(owner) => {
                let mut stmt = db
                    .prepare(&format!(
                        "{OBJECT_SELECT} WHERE owner = ?1 AND id > ?2 ORDER BY id LIMIT ?3"
                    ))
                    .map_err(sql)?;
                let rows = stmt
                    .query_map(params![owner, after, limit as i64], object_row)
                    .map_err(sql)?;
                rows.collect::<Result<Vec<_>, _>>()
            }
            None => {
                let mut stmt = db
                    .prepare(&format!(
                        "{OBJECT_SELECT} WHERE id > ?1 ORDER BY id LIMIT ?2"
                    ))
                    .map_err(sql)?;
                let rows = stmt
                    .query_map(params![after, limit as i64], object_row)
                    .map_err(sql)?;
                rows.collect::<Result<Vec<_>, _>>()
            }
        };
        rows.map_err(sql)?.into_iter().map(finish_object).collect()
    }

    fn object_count(&self) -> Result<u64, WorldError> {
        let db = self.lock()?;
        count(&db, "SELECT COUNT(*) FROM objects")
    }

    fn log_after(&self, generation: u64) -> Result<Vec<Applied>, WorldError> {
        let db = self.lock()?;
        let mut stmt = db
            .prepare(
                "SELECT generation, object, model, transform FROM log
                 WHERE generation > ?1 ORDER BY generation",
            )
            .map_err(sql)?;
        let rows = stmt
            .query_map([generation as i64], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, i64>(1)?,
                    r.get::<_, Option<i64>>(2)?,
                    r.get::<_, Option<Vec<u8>>>(3)?,
                ))
            })
            .map_err(sql)?;
        rows.map(|r| {
            let (generation, object, model, transform) = r.map_err(sql)?;
            let state = match (model, transform) {
                (Some(model), Some(t)) => Some((model as u64, transform_of(&t)?)),
                _ => None,
            };
            Ok(Applied {
                generation: generation as u64,
                object: object as u64,
                state,
            })
        })
        .collect()
    }

    fn add_token(&self, user: &User, token_hash: &str) -> Result<(), WorldError> {
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        tx.execute(
            "INSERT INTO users (name, max_objects, max_bytes) VALUES (?1, ?2, ?3)
             ON CONFLICT(name) DO UPDATE SET max_objects = ?2, max_bytes = ?3",
            params![
                user.name,
                user.max_objects.map(|v| v as i64),
                user.max_bytes.map(|v| v as i64)
            ],
        )
        .map_err(sql)?;
        tx.execute(
            "INSERT INTO tokens (hash, user) VALUES (?1, ?2)",
            params![token_hash, user.name],
        )
        .map_err(sql)?;
        tx.commit().map_err(sql)?;
        Ok(())
    }

    fn user_of_token(&self, token_hash: &str) -> Result<Option<User>, WorldError> {
        let db = self.lock()?;
        db.query_row(
            "SELECT users.name, users.max_objects, users.max_bytes FROM tokens
             JOIN users ON users.name = tokens.user WHERE tokens.hash = ?1",
            [token_hash],
            |r| {
                Ok(User {
                    name: r.get(0)?,
                    max_objects: r.get::<_, Option<i64>>(1)?.map(|v| v as u64),
                    max_bytes: r.get::<_, Option<i64>>(2)?.map(|v| v as u64),
                })
            },
        )
        .optional()
        .map_err(sql)
    }

    fn aggregate_entries(&self) -> Result<Vec<(String, String)>, WorldError> {
        let db = self.lock()?;
        let mut stmt = db
            .prepare("SELECT key, entry FROM aggregates")
            .map_err(sql)?;
        let rows = stmt
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
            .map_err(sql)?;
        rows.collect::<Result<_, _>>().map_err(sql)
    }

    fn put_aggregate_entries(&self, entries: &[(String, String)]) -> Result<(), WorldError> {
        if entries.is_empty() {
            return Ok(());
        }
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        {
            let mut stmt = tx
                .prepare("INSERT OR REPLACE INTO aggregates (key, entry) VALUES (?1, ?2)")
                .map_err(sql)?;
            for (key, entry) in entries {
                stmt.execute(params![key, entry]).map_err(sql)?;
            }
        }
        tx.commit().map_err(sql)
    }

    fn retain_aggregate_entries(&self, keys: &[String]) -> Result<(), WorldError> {
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        tx.execute_batch(
            "CREATE TEMP TABLE IF NOT EXISTS keep (key TEXT PRIMARY KEY); DELETE FROM keep;",
        )
        .map_err(sql)?;
        {
            let mut stmt = tx
                .prepare("INSERT OR IGNORE INTO keep (key) VALUES (?1)")
                .map_err(sql)?;
            for key in keys {
                stmt.execute([key]).map_err(sql)?;
            }
        }
        tx.execute(
            "DELETE FROM aggregates WHERE key NOT IN (SELECT key FROM keep)",
            [],
        )
        .map_err(sql)?;
        tx.execute("DELETE FROM keep", []).map_err(sql)?;
        tx.commit().map_err(sql)
    }

    fn remove_aggregate_entries(&self, keys: &[String]) -> Result<(), WorldError> {
        if keys.is_empty() {
            return Ok(());
        }
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        {
            let mut stmt = tx
                .prepare("DELETE FROM aggregates WHERE key = ?1")
                .map_err(sql)?;
            for key in keys {
                stmt.execute([key]).map_err(sql)?;
            }
        }
        tx.commit().map_err(sql)
    }

    fn published(&self) -> Result<Published, WorldError> {
        let db = self.lock()?;
        match get_key(&db, "published")? {
            Some(json) => serde_json::from_str(&json).map_err(|e| {
                WorldError::Inconsistent(format!("the published record does not parse: {e}"))
            }),
            None => Ok(Published::default()),
        }
    }

    fn publish(&self, published: &Published) -> Result<(), WorldError> {
        let db = self.lock()?;
        let json = serde_json::to_string(published)
            .map_err(|e| WorldError::Inconsistent(e.to_string()))?;
        set_key(&db, "published", &json)
    }

    fn snapshot(&self) -> Result<Option<Snapshot>, WorldError> {
        let db = self.lock()?;
        get_key(&db, "snapshot")?
            .map(|json| {
                serde_json::from_str(&json).map_err(|e| {
                    WorldError::Inconsistent(format!("the snapshot record does not parse: {e}"))
                })
            })
            .transpose()
    }

    fn put_snapshot(&self, snapshot: &Snapshot) -> Result<(), WorldError> {
        let mut db = self.lock()?;
        let tx = db.transaction().map_err(sql)?;
        let json =
            serde_json::to_string(snapshot).map_err(|e| WorldError::Inconsistent(e.to_string()))?;
        set_key(&tx, "snapshot", &json)?;
        tx.execute(
            "DELETE FROM log WHERE generation <= ?1",
            [snapshot.generation as i64],
        )
        .map_err(sql)?;
        tx.commit().map_err(sql)
    }
}

const MODEL_SELECT: &str = "SELECT number, id, asset, name, owner, bytes, stats FROM models";
const OBJECT_SELECT: &str = "SELECT id, model, transform, owner, generation FROM objects";

type RawModel = (i64, String, String, String, Option<String>, i64, String);

fn model_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<RawModel> {
    Ok((
        r.get(0)?,
        r.get(1)?,
        r.get(2)?,
        r.get(3)?,
        r.get(4)?,
        r.get(5)?,
        r.get(6)?,
    ))
}

fn finish_model(raw: RawModel) -> Result<ModelRow, WorldError> {
    let (number, id, asset, name, owner, bytes, stats) = raw;
    Ok(ModelRow {
        number: number as u64,
        id,
        asset,
        name,
        owner,
        bytes: bytes as u64,
        stats: serde_json::from_str(&stats)
            .map_err(|e| WorldError::Inconsistent(format!("model stats do not parse: {e}")))?,
    })
}

fn model_by_id(db: &Connection, id: &str) -> Result<Option<ModelRow>, WorldError> {
    db.query_row(&format!("{MODEL_SELECT} WHERE id = ?1"), [id], model_row)
        .optional()
        .map_err(sql)?
        .map(finish_model)
        .transpose()
}

type RawObject = (i64, i64, Vec<u8>, Option<String>, i64);

fn object_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<RawObject> {
    Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?))
}

fn finish_object(raw: RawObject) -> Result<ObjectRow, WorldError> {
    let (id, model, transform, owner, generation) = raw;
    Ok(ObjectRow {
        id: id as u64,
        model: model as u64,
        transform: transform_of(&transform)?,
        owner,
        generation: generation as u64,
    })
}

fn object_by_id(db: &Connection, id: u64) -> Result<Option<ObjectRow>, WorldError> {
    db.query_row(
        &format!("{OBJECT_SELECT} WHERE id = ?1"),
        [id as i64],
        object_row,
    )
    .optional()
    .map_err(sql)?
    .map(finish_object)
    .transpose()
}

/// The object `id`, if `user` may change it (the world may change any).
fn owned_object(
    tx: &Transaction<'_>,
    id: u64,
    user: Option<&str>,
) -> Result<ObjectRow, WorldError> {
    let row =
        object_by_id(tx, id)?.ok_or_else(|| WorldError::NotFound(format!("no object {id}")))?;
    if let Some(user) = user {
        if row.owner.as_deref() != Some(user) {
            return Err(WorldError::Forbidden(format!(
                "object {id} belongs to {}",
                row.owner.as_deref().unwrap_or("the world")
            )));
        }
    }
    Ok(row)
}

/// Records the descriptors of a stored GLB.
fn insert_descriptors(
    db: &Connection,
    asset: &str,
    d: &ModelDescriptors,
) -> Result<(), WorldError> {
    db.execute(
        "INSERT OR REPLACE INTO descriptors (asset, zernike, csd, centre, radius)
         VALUES (?1, ?2, ?3, ?4, ?5)",
        params![
            asset,
            bytes_of(&d.zernike),
            bytes_of(&d.csd),
            bytes_of(&d.centre),
            f64::from(d.radius)
        ],
    )
    .map_err(sql)?;
    Ok(())
}

fn insert_levels(db: &Connection, asset: &str, levels: &[ModelLevel]) -> Result<(), WorldError> {
    let text = serde_json::to_string(levels)
        .map_err(|e| WorldError::Inconsistent(format!("levels of {asset}: {e}")))?;
    db.execute(
        "INSERT OR REPLACE INTO levels (asset, levels) VALUES (?1, ?2)",
        params![asset, text],
    )
    .map_err(sql)?;
    Ok(())
}

fn parse_levels(asset: &str, text: &str) -> Result<Vec<ModelLevel>, WorldError> {
    serde_json::from_str(text)
        .map_err(|e| WorldError::Inconsistent(format!("levels of {asset} do not parse: {e}")))
}

/// Refuses a model of `bytes` for `owner` past their `max_bytes`.
fn check_bytes_quota(db: &Connection, owner: &str, bytes: u64) -> Result<(), WorldError> {
    let limit: Option<Option<i64>> = db
        .query_row(
            "SELECT max_bytes FROM users WHERE name = ?1",
            [owner],
            |r| r.get(0),
        )
        .optional()
        .map_err(sql)?;
    if let Some(Some(max)) = limit {
        let used: i64 = db
            .query_row(
                "SELECT COALESCE(SUM(bytes), 0) FROM models WHERE owner = ?1",
                [owner],
                |r| r.get(0),
            )
            .map_err(sql)?;
        if used.saturating_add(bytes as i64) > max {
            return Err(WorldError::QuotaExceeded(format!(
                "{owner} has stored {used} of {max} bytes of models; this one is {bytes}"
            )));
        }
    }
    Ok(())
}

/// Refuses one more object for `user` past their `max_objects`.
fn check_object_quota(tx: &Transaction<'_>, user: &str) -> Result<(), WorldError> {
    let limit: Option<Option<i64>> = tx
        .query_row(
            "SELECT max_objects FROM users WHERE name = ?1",
            [user],
            |r| r.get(0),
        )
        .optional()
        .map_err(sql)?;
    if let Some(Some(max)) = limit {
        let owned: i64 = tx
            .query_row(
                "SELECT COUNT(*) FROM objects WHERE owner = ?1",
                [user],
                |r| r.get(0),
            )
            .map_err(sql)?;
        if owned >= max {
            return Err(WorldError::QuotaExceeded(format!(
                "{user} owns {owned} of at most {max} objects"
            )));
        }
    }
    Ok(())
}

fn count(db: &Connection, query: &str) -> Result<u64, WorldError> {
    db.query_row(query, [], |r| r.get::<_, i64>(0))
        .map(|n| n as u64)
        .map_err(sql)
}

fn get_key(db: &Connection, key: &str) -> Result<Option<String>, WorldError> {
    db.query_row("SELECT value FROM world WHERE key = ?1", [key], |r| {
        r.get(0)
    })
    .optional()
    .map_err(sql)
}

fn get_u64(db: &Connection, key: &str) -> Result<u64, WorldError> {
    get_key(db, key)?.map_or(Ok(0), |v| {
        v.parse()
            .map_err(|_| WorldError::Inconsistent(format!("world.{key} is {v:?}")))
    })
}

fn set_key(db: &Connection, key: &str, value: &str) -> Result<(), WorldError> {
    db.execute(
        "INSERT INTO world (key, value) VALUES (?1, ?2)
         ON CONFLICT(key) DO UPDATE SET value = ?2",
        params![key, value],
    )
    .map_err(sql)?;
    Ok(())
}

/// A transform as 12 little-endian f32, by columns (glam's `to_cols_array`).
fn transform_bytes(t: &Affine3A) -> Vec<u8> {
    bytes_of(&t.to_cols_array())
}

fn transform_of(bytes: &[u8]) -> Result<Affine3A, WorldError> {
    let v = floats(bytes);
    let cols: [f32; 12] = v
        .try_into()
        .map_err(|_| WorldError::Inconsistent("a stored transform is not 12 floats".into()))?;
    Ok(Affine3A::from_cols_array(&cols))
}

fn bytes_of(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn floats(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn sql(e: rusqlite::Error) -> WorldError {
    WorldError::Database(e.to_string())
}

fn sql_at(path: &Path, e: rusqlite::Error) -> WorldError {
    WorldError::Database(format!("{}: {e}", path.display()))
}
