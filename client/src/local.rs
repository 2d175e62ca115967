//! [`LocalCut`]: the cut a stream client holds, kept by applying the server's resets and
//! deltas in order (`DESIGN.md`, "WebSocket messages"), and checked as it goes: a delta that
//! does not follow the one before, removes what is not held or adds what is, is refused whole
//! ([`ApplyError`]); [`LocalCut::check_complete`] asks that the entries count every object of
//! the generation exactly once; [`LocalCut::same_as`] compares it with a one-shot cut.

use std::collections::{BTreeSet, HashMap, HashSet};

use horizon_protocol::{CutResponse, Entry, EntryKind, ServerMessage, StoppedBy};

/// A cut kept by applying a stream's messages: the entries by id, and what the last message
/// said of the world.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LocalCut {
    entries: HashMap<String, Entry>,
    generation: u64,
    published: u64,
    objects: u64,
    stopped_by: Option<StoppedBy>,
    seq: u64,
    view: u64,
}

impl LocalCut {
    /// An empty cut that has applied nothing (`seq` 0).
    pub fn new() -> Self {
        Self::default()
    }

    /// Applies one message of the stream, all of it or (on an error) none of it.
    ///
    /// A reset replaces everything; its `seq` must follow the last one applied, or be 1 (a new
    /// connection starts over). A delta's `seq` must follow the last one applied (and a reset
    /// must have come first); every id it removes must be held (once), every id it adds must
    /// not be held after the removals (nor added twice), and every id an addition replaces
    /// must be gone after the delta (removed by it, or not held before). Removals go first,
    /// then additions. An error message changes nothing and is not an error here: the
    /// connection goes on, and the caller decides what it means.
    ///
    /// # Errors
    /// The first rule the message breaks, and the cut is unchanged.
    pub fn apply(&mut self, message: &ServerMessage) -> Result<(), ApplyError> {
        match message {
            ServerMessage::Reset {
                seq,
                view,
                generation,
                published,
                objects,
                entries,
                stopped_by,
            } => {
                if *seq != self.seq + 1 && *seq != 1 {
                    return Err(ApplyError::Sequence {
                        expected: self.seq + 1,
                        got: *seq,
                    });
                }
                let mut held = HashMap::with_capacity(entries.len());
                for entry in entries {
                    if held.insert(entry.id.clone(), entry.clone()).is_some() {
                        return Err(ApplyError::DuplicateEntry(entry.id.clone()));
                    }
                }
                self.entries = held;
                self.set_header(*seq, *view, *generation, *published, *objects, *stopped_by);
                Ok(())
            }
            ServerMessage::Delta {
                seq,
                view,
                generation,
                published,
                objects,
                add,
                remove,
                stopped_by,
            } => {
                if self.seq == 0 {
                    return Err(ApplyError::NoReset(*seq));
                }
                if *seq != self.seq + 1 {
                    return Err(ApplyError::Sequence {
                        expected: self.seq + 1,
                        got: *seq,
                    });
                }
                // Check everything first, so that a refused delta changes nothing.
                let mut removed = HashSet::with_capacity(remove.len());
                for r in remove {
                    if !self.entries.contains_key(&r.id) {
                        return Err(ApplyError::RemovedUnknown(r.id.clone()));
                    }
                    if !removed.insert(r.id.as_str()) {
                        return Err(ApplyError::RemovedTwice(r.id.clone()));
                    }
                }
                let mut added = HashSet::with_capacity(add.len());
                for a in add {
                    let id = a.entry.id.as_str();
                    if self.entries.contains_key(id) && !removed.contains(id) {
                        return Err(ApplyError::AddedPresent(id.to_owned()));
                    }
                    if !added.insert(id) {
                        return Err(ApplyError::AddedTwice(id.to_owned()));
                    }
                }
                for a in add {
                    for r in &a.replaces {
                        let r = r.as_str();
                        let gone = removed.contains(r)
                            || (!self.entries.contains_key(r) && !added.contains(r));
                        if !gone {
                            return Err(ApplyError::ReplacesPresent {
                                entry: a.entry.id.clone(),
                                replaces: r.to_owned(),
                            });
                        }
                    }
                }
                // An addition that reuses a held entry's assets and placements takes them
                // before the removals: it must name one it replaces, held before the delta.
                let mut entries = Vec::with_capacity(add.len());
                for a in add {
                    let mut entry = a.entry.clone();
                    if let Some(reuse) = &a.reuses {
                        let held = self
                            .entries
                            .get(&reuse.entry)
                            .filter(|_| a.replaces.contains(&reuse.entry))
                            .filter(|_| a.entry.assets.is_empty() && a.entry.placements.is_empty());
                        let Some(held) = held else {
                            return Err(ApplyError::ReusesUnknown {
                                entry: a.entry.id.clone(),
                                reuses: reuse.entry.clone(),
                            });
                        };
                        reuse.fill(held, &mut entry);
                    }
                    entries.push(entry);
                }
                for r in remove {
                    self.entries.remove(&r.id);
                }
                for entry in entries {
                    self.entries.insert(entry.id.clone(), entry);
                }
                self.set_header(*seq, *view, *generation, *published, *objects, *stopped_by);
                Ok(())
            }
            ServerMessage::Error { .. } => Ok(()),
        }
    }

    /// Checks that the entries count every object exactly once: the sum of their `covers` is
    /// `objects` (ids are unique: they are the keys).
    ///
    /// # Errors
    /// [`Incomplete`] with the sum and the count.
    pub fn check_complete(&self) -> Result<(), Incomplete> {
        let covered: u64 = self.entries.values().map(|e| e.covers).sum();
        if covered == self.objects {
            Ok(())
        } else {
            Err(Incomplete::Covers {
                covered,
                objects: self.objects,
            })
        }
    }

    /// Compares this cut with a one-shot cut: the same generation, published generation,
    /// object count, stopping budget, and the same entries as a set by id, each equal field
    /// for field (floats exactly: the server computes both the same way), except an
    /// object's level of detail and what follows from it: the server keeps a level a stream
    /// holds while it stays within a margin of the threshold, where a one-shot cut has no
    /// level to keep.
    ///
    /// # Errors
    /// [`Mismatch`], listing every difference.
    pub fn same_as(&self, fresh: &CutResponse) -> Result<(), Mismatch> {
        let mut mismatch = Mismatch::default();
        let mut header = |field: &str, local: String, fresh: String| {
            if local != fresh {
                mismatch
                    .header
                    .push(format!("{field}: local {local}, fresh {fresh}"));
            }
        };
        header(
            "generation",
            self.generation.to_string(),
            fresh.generation.to_string(),
        );
        header(
            "published",
            self.published.to_string(),
            fresh.published.to_string(),
        );
        header(
            "objects",
            self.objects.to_string(),
            fresh.objects.to_string(),
        );
        header(
            "stopped_by",
            format!("{:?}", self.stopped_by),
            format!("{:?}", fresh.stopped_by),
        );
        // An object's level of detail may differ within the server's hysteresis: entries are
        // matched by their content without the level (`o:<id>@<placed>`), and the fields
        // that follow from the level are compared only where the levels agree.
        let local: HashMap<&str, &Entry> = self
            .entries
            .values()
            .map(|e| (without_level(&e.id), e))
            .collect();
        let mut seen = HashSet::with_capacity(fresh.entries.len());
        for entry in &fresh.entries {
            let key = without_level(&entry.id);
            if !seen.insert(key) {
                mismatch
                    .header
                    .push(format!("the fresh cut holds {} twice", entry.id));
                continue;
            }
            match local.get(key) {
                None => mismatch.missing.push(entry.id.clone()),
                Some(local) => {
                    if let Some(field) = first_difference(local, entry) {
                        mismatch.differing.push((entry.id.clone(), field));
                    }
                }
            }
        }
        mismatch.extra = local
            .iter()
            .filter(|(key, _)| !seen.contains(*key))
            .map(|(_, e)| e.id.clone())
            .collect();
        mismatch.missing.sort();
        mismatch.extra.sort();
        mismatch.differing.sort();
        if mismatch.is_empty() {
            Ok(())
        } else {
            Err(mismatch)
        }
    }

    /// Whether a reset has been applied.
    pub fn started(&self) -> bool {
        self.seq > 0
    }

    /// The entries, by id.
    pub fn entries(&self) -> &HashMap<String, Entry> {
        &self.entries
    }

    /// The entry `id`, if held.
    pub fn get(&self, id: &str) -> Option<&Entry> {
        self.entries.get(id)
    }

    /// How many entries are held.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no entry is held.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The generation whose objects the cut covers.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// The generation whose aggregates it names.
    pub fn published(&self) -> u64 {
        self.published
    }

    /// Objects at `generation`.
    pub fn objects(&self) -> u64 {
        self.objects
    }

    /// The budget that stopped the cut's refinement.
    pub fn stopped_by(&self) -> Option<StoppedBy> {
        self.stopped_by
    }

    /// The `seq` of the last message applied (0: none).
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// The id of the last view the server applied.
    pub fn view(&self) -> u64 {
        self.view
    }

    /// The hashes of every asset the held entries need, each once.
    pub fn asset_hashes(&self) -> BTreeSet<&str> {
        self.entries
            .values()
            .flat_map(|e| e.assets.iter().map(|a| a.hash.as_str()))
            .collect()
    }

    fn set_header(
        &mut self,
        seq: u64,
        view: u64,
        generation: u64,
        published: u64,
        objects: u64,
        stopped_by: Option<StoppedBy>,
    ) {
        self.seq = seq;
        self.view = view;
        self.generation = generation;
        self.published = published;
        self.objects = objects;
        self.stopped_by = stopped_by;
    }
}

/// Checks a one-shot cut as [`LocalCut::check_complete`] checks a kept one: unique ids, and
/// `covers` summing to `objects`.
///
/// # Errors
/// [`Incomplete`].
pub fn check_cut(cut: &CutResponse) -> Result<(), Incomplete> {
    let mut ids = HashSet::with_capacity(cut.entries.len());
    if let Some(e) = cut.entries.iter().find(|e| !ids.insert(e.id.as_str())) {
        return Err(Incomplete::Duplicate(e.id.clone()));
    }
    let covered: u64 = cut.entries.iter().map(|e| e.covers).sum();
    if covered == cut.objects {
        Ok(())
    } else {
        Err(Incomplete::Covers {
            covered,
            objects: cut.objects,
        })
    }
}

/// An entry id without its level of detail: `o:<id>@<placed>/<level>` -> `o:<id>@<placed>`,
/// `n:<node>@i<content>/<levels>` -> `n:<node>@i<content>`.
fn without_level(id: &str) -> &str {
    let levelled = id.starts_with("o:") || id.contains("@i");
    match id.rfind('/').filter(|_| levelled) {
        Some(slash) => &id[..slash],
        None => id,
    }
}

/// The first field in which two entries of the same content differ, by name; an object's
/// level (an instances entry's levels) is not compared, and what follows from it (id,
/// assets, placements, bytes, triangles, draw calls) only when the levels agree.
fn first_difference(a: &Entry, b: &Entry) -> Option<String> {
    // Instances are at the same levels when their ids, which hash the levels, agree.
    let at_level = a.level == b.level && (a.kind != EntryKind::Instances || a.id == b.id);
    let fields: [(&str, bool); 11] = [
        ("id", !at_level || a.id == b.id),
        ("kind", a.kind == b.kind),
        ("assets", !at_level || a.assets == b.assets),
        ("placements", !at_level || a.placements == b.placements),
        ("pending", a.pending == b.pending),
        ("bytes", !at_level || a.bytes == b.bytes),
        ("triangles", !at_level || a.triangles == b.triangles),
        ("draw_calls", !at_level || a.draw_calls == b.draw_calls),
        ("center", a.center == b.center),
        ("radius", a.radius == b.radius),
        ("covers", a.covers == b.covers),
    ];
    fields.iter().find(|(_, same)| !same).map(|(name, _)| {
        let show = |e: &Entry| -> String {
            serde_json::to_value(e)
                .ok()
                .and_then(|v| v.get(*name).map(ToString::to_string))
                .unwrap_or_default()
        };
        format!("{name}: local {}, fresh {}", show(a), show(b))
    })
}

/// Why a message was refused: the cut is as it was before it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ApplyError {
    /// The message's `seq` does not follow the last one applied.
    #[error("seq {got} where {expected} was expected")]
    Sequence {
        /// The last applied plus one.
        expected: u64,
        /// The message's.
        got: u64,
    },
    /// A delta came before any reset.
    #[error("delta seq {0} before any reset")]
    NoReset(u64),
    /// A reset holds an id twice.
    #[error("the reset holds {0} twice")]
    DuplicateEntry(String),
    /// A delta removes an id that is not held.
    #[error("the delta removes {0}, which is not held")]
    RemovedUnknown(String),
    /// A delta removes an id twice.
    #[error("the delta removes {0} twice")]
    RemovedTwice(String),
    /// A delta adds an id that is still held after its removals.
    #[error("the delta adds {0}, which is already held")]
    AddedPresent(String),
    /// A delta adds an id twice.
    #[error("the delta adds {0} twice")]
    AddedTwice(String),
    /// An addition replaces an entry that is still held after the delta.
    #[error("{entry} replaces {replaces}, which is still held")]
    ReplacesPresent {
        /// The added entry.
        entry: String,
        /// The id it names in `replaces`.
        replaces: String,
    },
    /// An addition reuses the assets and placements of an entry that was not held before the
    /// delta, that it does not replace, or while sending assets or placements of its own.
    #[error("{entry} reuses the assets and placements of {reuses}, which it cannot")]
    ReusesUnknown {
        /// The added entry.
        entry: String,
        /// The id it names in `reuses`.
        reuses: String,
    },
}

/// A cut that does not count every object exactly once.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Incomplete {
    /// The entries' `covers` do not add up to `objects`.
    #[error("the entries cover {covered} objects of {objects}")]
    Covers {
        /// The sum of `covers`.
        covered: u64,
        /// The cut's `objects`.
        objects: u64,
    },
    /// An id appears twice.
    #[error("the cut holds {0} twice")]
    Duplicate(String),
}

/// How a kept cut differs from a one-shot cut.
#[derive(Clone, Debug, Default, PartialEq, Eq, thiserror::Error)]
#[error("{}", self.describe())]
pub struct Mismatch {
    /// Differences outside the entries (generation, published, objects, stopped_by).
    pub header: Vec<String>,
    /// Ids the fresh cut holds and the kept one does not.
    pub missing: Vec<String>,
    /// Ids the kept cut holds and the fresh one does not.
    pub extra: Vec<String>,
    /// Ids both hold, with the first field that differs.
    pub differing: Vec<(String, String)>,
}

impl Mismatch {
    /// Whether there is no difference.
    pub fn is_empty(&self) -> bool {
        self.header.is_empty()
            && self.missing.is_empty()
            && self.extra.is_empty()
            && self.differing.is_empty()
    }

    /// One line: every difference, the long lists cut short.
    fn describe(&self) -> String {
        fn list(items: &[String]) -> String {
            let shown: Vec<&str> = items.iter().take(8).map(String::as_str).collect();
            let more = items.len().saturating_sub(shown.len());
            if more > 0 {
                format!("{} (and {more} more)", shown.join(", "))
            } else {
                shown.join(", ")
            }
        }
        let mut parts = self.header.clone();
        if !self.missing.is_empty() {
            parts.push(format!(
                "{} entries only in the fresh cut: {}",
                self.missing.len(),
                list(&self.missing)
            ));
        }
        if !self.extra.is_empty() {
            parts.push(format!(
                "{} entries only in the kept cut: {}",
                self.extra.len(),
                list(&self.extra)
            ));
        }
        if !self.differing.is_empty() {
            let items: Vec<String> = self
                .differing
                .iter()
                .map(|(id, field)| format!("{id} ({field})"))
                .collect();
            parts.push(format!(
                "{} entries differ: {}",
                self.differing.len(),
                list(&items)
            ));
        }
        format!(
            "the kept cut differs from the fresh one: {}",
            parts.join("; ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use horizon_protocol::{
        Addition, Asset, AssetRole, EntryKind, Placement, Removal, RemoveReason,
    };

    fn entry(id: &str, covers: u64) -> Entry {
        Entry {
            id: id.to_owned(),
            kind: if id.starts_with("o:") {
                EntryKind::Object
            } else {
                EntryKind::Aggregate
            },
            assets: vec![Asset {
                hash: format!("{:0>64}", id.len()),
                bytes: 100,
                role: AssetRole::Mesh,
            }],
            placements: vec![Placement {
                asset: format!("{:0>64}", id.len()),
                matrix: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            }],
            level: 0,
            pending: false,
            bytes: 100,
            triangles: 12,
            draw_calls: 1,
            center: [0.0, 1.0, 2.0],
            radius: 1.5,
            covers,
            impostor: None,
        }
    }

    fn reset(seq: u64, entries: Vec<Entry>) -> ServerMessage {
        let objects = entries.iter().map(|e| e.covers).sum();
        ServerMessage::Reset {
            seq,
            view: 1,
            generation: 5,
            published: 4,
            objects,
            entries,
            stopped_by: None,
        }
    }

    fn add(e: Entry, replaces: &[&str]) -> Addition {
        Addition {
            entry: e,
            replaces: replaces.iter().map(|s| (*s).to_owned()).collect(),
            reuses: None,
        }
    }

    fn remove(id: &str) -> Removal {
        Removal {
            id: id.to_owned(),
            reason: RemoveReason::Refined,
        }
    }

    fn delta(seq: u64, objects: u64, add: Vec<Addition>, remove: Vec<Removal>) -> ServerMessage {
        ServerMessage::Delta {
            seq,
            view: 2,
            generation: 6,
            published: 4,
            objects,
            add,
            remove,
            stopped_by: Some(StoppedBy::MaxEntries),
        }
    }

    fn started() -> LocalCut {
        let mut cut = LocalCut::new();
        cut.apply(&reset(1, vec![entry("n:1@a", 3), entry("o:7@2", 1)]))
            .expect("reset");
        cut
    }

    fn as_response(cut: &LocalCut) -> CutResponse {
        let mut entries: Vec<Entry> = cut.entries().values().cloned().collect();
        entries.sort_by(|a, b| a.id.cmp(&b.id));
        CutResponse {
            generation: cut.generation(),
            published: cut.published(),
            objects: cut.objects(),
            entries,
            stopped_by: cut.stopped_by(),
        }
    }

    #[test]
    fn a_reset_then_a_delta_refine_the_cut() {
        let mut cut = started();
        assert_eq!(cut.len(), 2);
        assert_eq!((cut.seq(), cut.generation(), cut.objects()), (1, 5, 4));
        cut.check_complete().expect("complete");
        // The aggregate is refined into its three objects.
        cut.apply(&delta(
            2,
            4,
            vec![
                add(entry("o:1@1", 1), &["n:1@a"]),
                add(entry("o:2@1", 1), &["n:1@a"]),
                add(entry("o:3@1", 1), &["n:1@a"]),
            ],
            vec![remove("n:1@a")],
        ))
        .expect("delta");
        assert_eq!(cut.len(), 4);
        assert!(cut.get("n:1@a").is_none());
        assert_eq!((cut.seq(), cut.view(), cut.generation()), (2, 2, 6));
        assert_eq!(cut.stopped_by(), Some(StoppedBy::MaxEntries));
        cut.check_complete().expect("complete");
        // A reset replaces everything, and a new connection's reset starts at 1 again.
        cut.apply(&reset(3, vec![entry("n:9@b", 4)]))
            .expect("reset");
        assert_eq!(cut.len(), 1);
        cut.apply(&reset(1, vec![entry("n:9@c", 4)]))
            .expect("reset");
        assert_eq!((cut.len(), cut.seq()), (1, 1));
        // An error message changes nothing.
        let before = cut.clone();
        cut.apply(&ServerMessage::Error {
            error: horizon_protocol::ErrorDetail {
                code: horizon_protocol::ErrorCode::BadQuery,
                message: "bad view".into(),
            },
        })
        .expect("an error message applies as nothing");
        assert_eq!(cut, before);
    }

    #[test]
    fn a_removed_id_may_come_back_in_the_same_delta() {
        let mut cut = started();
        let mut moved = entry("o:7@2", 1);
        moved.radius = 9.0;
        cut.apply(&delta(
            2,
            4,
            vec![add(moved.clone(), &["o:7@2"])],
            vec![remove("o:7@2")],
        ))
        .expect("delta");
        assert_eq!(cut.get("o:7@2"), Some(&moved));
    }

    #[test]
    fn an_addition_reusing_held_placements_takes_them_renamed_and_refuses_otherwise() {
        let placed = |asset: &str, x: f32| Placement {
            asset: asset.to_owned(),
            matrix: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, x, 0.0, 0.0],
        };
        let asset = |hash: &str, bytes: u64| Asset {
            hash: hash.to_owned(),
            bytes,
            role: AssetRole::Model,
        };
        let mut held = entry("n:4@i1/a", 3);
        held.assets = vec![asset("m0", 100), asset("m1", 50)];
        held.placements = vec![placed("m0", 1.0), placed("m1", 2.0), placed("m0", 3.0)];
        let mut cut = LocalCut::new();
        cut.apply(&reset(1, vec![held, entry("o:7@2", 1)]))
            .expect("reset");
        // The same objects with model m0 at another level: its placements, renamed.
        let relevel = |seq: u64, reuses: &str, replaces: &[&str]| {
            let mut a = add(entry("n:4@i1/b", 3), replaces);
            a.entry.assets = Vec::new();
            a.entry.placements = Vec::new();
            a.reuses = Some(horizon_protocol::Reuse {
                entry: reuses.to_owned(),
                assets: vec![horizon_protocol::Renamed {
                    from: "m0".to_owned(),
                    to: "m0-level-1".to_owned(),
                    bytes: 30,
                }],
            });
            delta(seq, 4, vec![a], vec![remove("n:4@i1/a")])
        };
        for bad in [
            relevel(2, "o:7@2", &["n:4@i1/a"]),
            relevel(2, "n:4@i1/a", &[]),
        ] {
            let before = cut.clone();
            let e = cut
                .apply(&bad)
                .expect_err("reuses what it does not replace");
            assert!(matches!(e, ApplyError::ReusesUnknown { .. }), "{e}");
            assert_eq!(cut, before);
        }
        cut.apply(&relevel(2, "n:4@i1/a", &["n:4@i1/a"]))
            .expect("a relevel");
        let got = cut.get("n:4@i1/b").expect("the new entry");
        assert_eq!(got.assets, vec![asset("m0-level-1", 30), asset("m1", 50)]);
        assert_eq!(
            got.placements,
            vec![
                placed("m0-level-1", 1.0),
                placed("m1", 2.0),
                placed("m0-level-1", 3.0)
            ]
        );
        assert!(cut.get("n:4@i1/a").is_none());
        cut.check_complete().expect("complete");
    }

    #[test]
    fn bad_deltas_are_refused_and_change_nothing() {
        let cut = started();
        let cases = [
            (
                delta(3, 4, vec![], vec![]),
                ApplyError::Sequence {
                    expected: 2,
                    got: 3,
                },
            ),
            (
                delta(1, 4, vec![], vec![]),
                ApplyError::Sequence {
                    expected: 2,
                    got: 1,
                },
            ),
            (
                delta(2, 4, vec![], vec![remove("n:404@x")]),
                ApplyError::RemovedUnknown("n:404@x".into()),
            ),
            (
                delta(2, 4, vec![], vec![remove("o:7@2"), remove("o:7@2")]),
                ApplyError::RemovedTwice("o:7@2".into()),
            ),
            (
                delta(2, 5, vec![add(entry("o:7@2", 1), &[])], vec![]),
                ApplyError::AddedPresent("o:7@2".into()),
            ),
            (
                delta(
                    2,
                    6,
                    vec![add(entry("o:8@2", 1), &[]), add(entry("o:8@2", 1), &[])],
                    vec![],
                ),
                ApplyError::AddedTwice("o:8@2".into()),
            ),
            (
                delta(2, 5, vec![add(entry("o:8@2", 1), &["n:1@a"])], vec![]),
                ApplyError::ReplacesPresent {
                    entry: "o:8@2".into(),
                    replaces: "n:1@a".into(),
                },
            ),
            (
                reset(3, vec![]),
                ApplyError::Sequence {
                    expected: 2,
                    got: 3,
                },
            ),
            (
                reset(2, vec![entry("o:1@1", 1), entry("o:1@1", 1)]),
                ApplyError::DuplicateEntry("o:1@1".into()),
            ),
        ];
        for (message, expected) in cases {
            let mut c = cut.clone();
            assert_eq!(c.apply(&message), Err(expected), "{message:?}");
            assert_eq!(c, cut, "a refused message changed the cut: {message:?}");
        }
        // The removal passes but an addition fails: the removal is not applied either.
        let mut c = cut.clone();
        let message = delta(
            2,
            4,
            vec![add(entry("o:9@2", 1), &[]), add(entry("o:7@2", 1), &[])],
            vec![remove("n:1@a")],
        );
        assert_eq!(
            c.apply(&message),
            Err(ApplyError::AddedPresent("o:7@2".into()))
        );
        assert_eq!(c, cut);
        // Replacing an entry that was gone before the delta is fine.
        let mut c = cut.clone();
        c.apply(&delta(
            2,
            5,
            vec![add(entry("o:9@2", 1), &["n:0@gone"])],
            vec![],
        ))
        .expect("replaces an entry already gone");
        // Nothing applies before a reset.
        let mut fresh = LocalCut::new();
        assert_eq!(
            fresh.apply(&delta(1, 0, vec![], vec![])),
            Err(ApplyError::NoReset(1))
        );
        assert!(!fresh.started());
    }

    #[test]
    fn completeness_is_the_sum_of_covers() {
        let mut cut = LocalCut::new();
        cut.apply(&ServerMessage::Reset {
            seq: 1,
            view: 1,
            generation: 2,
            published: 2,
            objects: 5,
            entries: vec![entry("n:1@a", 3), entry("o:7@2", 1)],
            stopped_by: None,
        })
        .expect("reset");
        assert_eq!(
            cut.check_complete(),
            Err(Incomplete::Covers {
                covered: 4,
                objects: 5
            })
        );
        let mut response = as_response(&started());
        check_cut(&response).expect("complete");
        response.entries.push(entry("o:7@2", 1));
        response.objects += 1;
        assert_eq!(
            check_cut(&response),
            Err(Incomplete::Duplicate("o:7@2".into()))
        );
    }

    #[test]
    fn same_as_compares_entries_by_id_field_for_field() {
        let cut = started();
        let mut fresh = as_response(&cut);
        fresh.entries.reverse();
        cut.same_as(&fresh).expect("equal in any order");

        let mut moved = fresh.clone();
        moved.entries[0].center[1] += 1e-6;
        let m = cut.same_as(&moved).expect_err("a moved centre differs");
        assert_eq!(m.differing.len(), 1);
        assert!(m.differing[0].1.starts_with("center"), "{m}");

        let mut other = fresh.clone();
        other.entries.pop();
        other.entries.push(entry("n:2@b", 1));
        other.generation += 1;
        let m = cut.same_as(&other).expect_err("different entries");
        assert_eq!(m.missing, ["n:2@b"]);
        assert_eq!(m.extra.len(), 1);
        assert_eq!(m.header.len(), 1, "{m}");
        assert!(
            m.to_string().contains("generation: local 5, fresh 6"),
            "{m}"
        );
    }
}
