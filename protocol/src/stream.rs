//! `GET /v1/stream`: a standing query over WebSocket, JSON text frames (`DESIGN.md`,
//! "WebSocket messages").
//!
//! The client sends [`ClientMessage::View`] whenever it likes and [`ClientMessage::Ack`] for
//! what it has applied. The server answers with a [`ServerMessage::Reset`] (the whole cut),
//! then [`ServerMessage::Delta`]s, each atomic and numbered by `seq`, which starts at 1 and
//! rises by one per reset or delta. Applied in order, the deltas keep the client's cut equal
//! to a one-shot `GET /v1/cut` at the same view and generation.

use serde::{Deserialize, Serialize};

use crate::cut::{Asset, Entry, Placement, View};
use crate::error::ErrorDetail;

/// A message from the client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ClientMessage {
    /// Where the viewer is now; replaces every earlier view.
    View {
        /// The client's number for this view, echoed by the reply that applies it.
        id: u64,
        /// The view.
        #[serde(flatten)]
        view: View,
    },
    /// The client has applied every message up to `seq`.
    Ack {
        /// The last `seq` applied.
        seq: u64,
    },
}

/// Why an entry left a client's cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RemoveReason {
    /// Replaced by finer entries (the viewer came closer).
    Refined,
    /// Replaced by a coarser entry (the viewer went away).
    Coarsened,
    /// Its object left the world.
    Deleted,
    /// Replaced by a new version of the same thing (a rebuilt aggregate, a moved object).
    Replaced,
}

/// One entry leaving a client's cut.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Removal {
    /// The entry's id.
    pub id: String,
    /// Why.
    pub reason: RemoveReason,
}

/// An entry joining a client's cut, with the entries it takes the place of: a client keeps
/// drawing those until this one has loaded (load before drop).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Addition {
    /// The entry.
    #[serde(flatten)]
    pub entry: Entry,
    /// Ids of removed entries that drew what this one draws.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub replaces: Vec<String>,
    /// Set when the entry's `assets` and `placements` are sent empty because they are those of
    /// an entry the client holds with some assets renamed: instances whose models moved to
    /// other levels of detail, every other asset and placement as it was ([`Reuse::fill`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reuses: Option<Reuse>,
}

/// The assets and placements of an entry the client holds before the delta, taken over by an
/// addition with the assets named in `assets` renamed: what an instances entry sends when only
/// the levels of detail of its models changed, instead of every asset and placement again.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Reuse {
    /// The held entry whose assets and placements the addition takes (one it replaces).
    pub entry: String,
    /// The assets renamed; every other asset stays as it was.
    pub assets: Vec<Renamed>,
}

/// One asset of a held entry becoming another: each of its placements, and its place in the
/// entry's `assets`, are the new asset's.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Renamed {
    /// The held asset's hash.
    pub from: String,
    /// The new asset's hash.
    pub to: String,
    /// The new asset's bytes.
    pub bytes: u64,
}

impl Reuse {
    /// Gives `entry` the assets and placements of `held` (the entry [`Reuse::entry`] names),
    /// in order, each asset named in [`Reuse::assets`] renamed.
    pub fn fill(&self, held: &Entry, entry: &mut Entry) {
        let renamed = |hash: &str| self.assets.iter().find(|r| r.from == hash);
        entry.assets = held
            .assets
            .iter()
            .map(|a| match renamed(&a.hash) {
                Some(r) => Asset {
                    hash: r.to.clone(),
                    bytes: r.bytes,
                    role: a.role,
                },
                None => a.clone(),
            })
            .collect();
        entry.placements = held
            .placements
            .iter()
            .map(|p| Placement {
                asset: renamed(&p.asset).map_or_else(|| p.asset.clone(), |r| r.to.clone()),
                matrix: p.matrix,
            })
            .collect();
    }
}

/// A message from the server.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// The whole cut: drop everything held and take these entries.
    Reset {
        /// This message's number.
        seq: u64,
        /// The id of the last view applied.
        view: u64,
        /// As in [`crate::CutResponse`].
        generation: u64,
        /// As in [`crate::CutResponse`].
        published: u64,
        /// As in [`crate::CutResponse`].
        objects: u64,
        /// The cut.
        entries: Vec<Entry>,
        /// As in [`crate::CutResponse`].
        stopped_by: Option<crate::StoppedBy>,
    },
    /// The change from the cut before to the cut now, applied as one step: removals, then
    /// additions.
    Delta {
        /// This message's number.
        seq: u64,
        /// The id of the last view applied.
        view: u64,
        /// As in [`crate::CutResponse`].
        generation: u64,
        /// As in [`crate::CutResponse`].
        published: u64,
        /// As in [`crate::CutResponse`].
        objects: u64,
        /// New entries.
        add: Vec<Addition>,
        /// Entries gone.
        remove: Vec<Removal>,
        /// As in [`crate::CutResponse`].
        stopped_by: Option<crate::StoppedBy>,
    },
    /// A bad message; the connection goes on.
    Error {
        /// What was wrong.
        error: ErrorDetail,
    },
}

impl ServerMessage {
    /// The `seq` of a reset or delta.
    pub fn seq(&self) -> Option<u64> {
        match self {
            Self::Reset { seq, .. } | Self::Delta { seq, .. } => Some(*seq),
            Self::Error { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cut::Budgets;

    #[test]
    fn an_addition_reusing_a_held_entry_names_it_and_the_assets_renamed() {
        let wire = r#"{"id": "n:4@i1/b", "kind": "instances", "assets": [], "placements": [],
            "level": 0, "bytes": 80, "triangles": 12, "draw_calls": 2, "center": [0, 0, 0],
            "radius": 5, "covers": 3, "replaces": ["n:4@i1/a"],
            "reuses": {"entry": "n:4@i1/a", "assets": [{"from": "m0", "to": "m0b", "bytes": 30}]}}"#;
        let a: Addition = serde_json::from_str(wire).expect("parse");
        let reuse = a.reuses.clone().expect("reuses");
        let again: Addition =
            serde_json::from_str(&serde_json::to_string(&a).expect("json")).expect("parse");
        assert_eq!(again, a);
        let asset = |hash: &str, bytes: u64| Asset {
            hash: hash.into(),
            bytes,
            role: crate::cut::AssetRole::Model,
        };
        let at = |hash: &str, x: f32| Placement {
            asset: hash.into(),
            matrix: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, x, 0.0, 0.0],
        };
        let mut held = a.entry.clone();
        held.assets = vec![asset("m0", 100), asset("m1", 50)];
        held.placements = vec![at("m1", 1.0), at("m0", 2.0), at("m0", 3.0)];
        let mut entry = a.entry;
        reuse.fill(&held, &mut entry);
        assert_eq!(entry.assets, vec![asset("m0b", 30), asset("m1", 50)]);
        assert_eq!(
            entry.placements,
            vec![at("m1", 1.0), at("m0b", 2.0), at("m0b", 3.0)]
        );
    }

    #[test]
    fn a_view_message_parses_with_defaults_and_checks() {
        let m: ClientMessage =
            serde_json::from_str(r#"{"type": "view", "id": 17, "eye": [1, 2, 3]}"#).expect("parse");
        let ClientMessage::View { id, view } = m else {
            panic!("not a view: {m:?}");
        };
        assert_eq!(id, 17);
        assert_eq!(view, View::at([1.0, 2.0, 3.0]));
        assert_eq!(view.check(), Ok(()));
        let with_budget: ClientMessage = serde_json::from_str(
            r#"{"type": "view", "id": 1, "eye": [0, 0, 0], "min_solid_angle": 0.01,
                "budgets": {"max_entries": 10, "max_bytes": 5}}"#,
        )
        .expect("parse");
        let ClientMessage::View { view, .. } = with_budget else {
            panic!("not a view");
        };
        assert_eq!(view.min_solid_angle, 0.01);
        assert_eq!(
            view.budgets,
            Budgets {
                max_entries: Some(10),
                max_bytes: Some(5),
                ..Budgets::default()
            }
        );
    }

    #[test]
    fn bad_views_are_refused() {
        for bad in [
            r#"{"type": "look", "id": 1, "eye": [0, 0, 0]}"#,
            r#"{"type": "view", "id": 1}"#,
            r#"{"type": "view", "id": 1, "eye": [0, 0]}"#,
            r#"{"type": "view", "id": -1, "eye": [0, 0, 0]}"#,
            r#"{"type": "view", "id": 1, "eye": [0, 0, 0], "budgets": {"max_entries": -4}}"#,
            r#"{"type": "view", "id": 1, "eye": [0, 0, 0], "budgets": {"max_things": 4}}"#,
            r#"{"type": "ack"}"#,
        ] {
            assert!(
                serde_json::from_str::<ClientMessage>(bad).is_err(),
                "{bad} parsed"
            );
        }
        let mut view = View::at([0.0, 0.0, 0.0]);
        assert_eq!(view.check(), Ok(()));
        view.min_solid_angle = 13.0;
        assert!(view.check().is_err());
        view.min_solid_angle = 0.0;
        assert!(view.check().is_err());
        view = View::at([f64::NAN, 0.0, 0.0]);
        assert!(view.check().is_err());
        view = View::at([0.0, 0.0, 0.0]);
        view.pixel_solid_angle = f64::INFINITY;
        assert!(view.check().is_err());
        view = View::at([0.0, 0.0, 0.0]);
        view.budgets.max_triangles = Some(0);
        assert!(view.check().is_err());
        view.budgets.max_triangles = None;
        view.budgets.max_entries = Some(crate::MAX_ENTRIES_LIMIT + 1);
        assert!(view.check().is_err());
    }

    #[test]
    fn server_messages_carry_their_type_tag() {
        let m = ServerMessage::Delta {
            seq: 2,
            view: 17,
            generation: 5,
            published: 4,
            objects: 10,
            add: Vec::new(),
            remove: vec![Removal {
                id: "o:3@5".into(),
                reason: RemoveReason::Deleted,
            }],
            stopped_by: None,
        };
        let json = serde_json::to_value(&m).expect("serialise");
        assert_eq!(json["type"], "delta");
        assert_eq!(json["remove"][0]["reason"], "deleted");
        assert_eq!(m.seq(), Some(2));
        let back: ServerMessage = serde_json::from_value(json).expect("parse");
        assert_eq!(back, m);
    }
}
