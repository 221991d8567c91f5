//! The session's state: objectives, constraints, generation settings, the gallery, the base
//! and live looks with their history, master, blackout and saved looks. Plain data with
//! the rules of how it changes; no I/O.

use std::collections::BTreeMap;
use std::ops::RangeInclusive;

use visobjd_method::gallery::Generation;
use visobjd_method::objective::Objective;
use visobjd_method::sampler::Constraints;
use visobjd_scene::Scene;
use visobjd_scene::look::{Look, LookFile};

use serde::{Deserialize, Serialize};

use super::Refusal;
use super::rules::Rules;

/// Base looks kept for undo (docs/osc.md; at least 32 were asked for).
pub const HISTORY: usize = 64;

/// Candidates per generate (`/vo/generate/count`, `session.json`).
pub const COUNT: RangeInclusive<u32> = 1..=1000;
/// Gallery entries at most (`/vo/generate/clusters`, `session.json`).
pub const CLUSTERS: RangeInclusive<u32> = 1..=64;
/// Seed settings: 0 is a new random seed each generate.
pub const SEED: RangeInclusive<u64> = 0..=visobjd_method::gallery::MAX_SEED;
/// Crossfade seconds (`/vo/fade`, `session.json`).
pub const FADE_S: RangeInclusive<f32> = 0.0..=600.0;

// What a session may hold of what its users name and add (docs/osc.md, "Limits"): far
// past what a show uses, and what bounds the state a main hands its backups to a size
// known beforehand (super::state_size). Each is checked where it is accepted (refused
// with a sentence, nothing changed) and where a state is restored from its files or taken
// from a main (what is past it is left out, with a sentence).

/// Characters of a saved look's label.
pub const MAX_LABEL: usize = 100;
/// Saved looks at once (numbered 1..=9999).
pub const MAX_LOOKS: usize = 1000;
/// Objectives at once.
pub const MAX_OBJECTIVES: usize = 64;
/// Characters of an objective's image name (a path inside the references folder).
pub const MAX_IMAGE_NAME: usize = 100;
/// Colours of an objective's palette (`generate.palette` is 1..=this).
pub const MAX_PALETTE: usize = 16;

/// An objective with the id OSC addresses use.
#[derive(Debug, Clone)]
pub struct Entry {
    /// 1-based, never reused within a session.
    pub id: u32,
    /// The objective.
    pub objective: Objective,
}

/// The last generate's result.
#[derive(Debug, Clone)]
pub struct Gallery {
    /// Candidates and entries.
    pub generation: Generation,
    /// The seed it was drawn with.
    pub seed: u64,
    /// Which generate of this run made it (1, 2, ...): caches of its renders (the web
    /// gallery's thumbnails) are keyed by it.
    pub serial: u64,
}

impl Gallery {
    /// Candidate index of entry `k`, member `m` (both 1-based), if they exist.
    pub fn candidate(&self, k: usize, m: usize) -> Option<&Look> {
        let members = self.generation.entries.get(k.checked_sub(1)?)?;
        let index = *members.get(m.checked_sub(1)?)?;
        self.generation.candidates.get(index)
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.generation.entries.len()
    }

    /// Whether the generate produced no entry at all.
    pub fn is_empty(&self) -> bool {
        self.generation.entries.is_empty()
    }
}

/// What a change of the base look came from, so fader moves coalesce into one undo step
/// and following the console knows when to stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Change {
    /// Pick, next, prev, recall: one undo step each; following the console stops.
    Step,
    /// A fader (light or group intensity/colour): consecutive ones are one undo step;
    /// following the console stops.
    Fader,
    /// A console grab (or the start of following): one undo step; following goes on.
    Grab,
    /// A followed console change: consecutive ones are one undo step.
    Follow,
}

/// Everything the engine keeps between messages.
#[derive(Debug, Clone)]
pub struct Session {
    /// Objectives in the order they were added.
    pub objectives: Vec<Entry>,
    /// The next objective id.
    pub next_id: u32,
    /// Per group: designated key.
    pub key_groups: Vec<bool>,
    /// Per group: locked.
    pub locked_groups: Vec<bool>,
    /// Per light: locked.
    pub locked_lights: Vec<bool>,
    /// The lights an Eos console last reported selected (`/eos/out/active/chan`).
    pub eos_selection: Vec<usize>,
    /// Ratios, saturation ranges, exclusions and pins.
    pub rules: Rules,
    /// Candidates per generate.
    pub count: u32,
    /// Entries at most.
    pub clusters: u32,
    /// 0: a new random seed each generate.
    pub seed: u64,
    /// Crossfade time for pick, next, prev, recall, undo, redo.
    pub fade_s: f32,
    /// The last gallery.
    pub gallery: Option<Gallery>,
    /// What generation starts from.
    pub base: Look,
    /// What is on stage (fades run toward it).
    pub live: Look,
    /// The gallery entry and member that is live, if the live look is one.
    pub entry: Option<(usize, usize)>,
    undo: Vec<Look>,
    redo: Vec<Look>,
    last_change: Option<Change>,
    /// Grand master, 0..1.
    pub master: f32,
    /// Blackout on.
    pub blackout: bool,
    /// Saved looks by number.
    pub looks: BTreeMap<u32, LookFile>,
    /// The base follows the console (`/vo/console/follow`), until a visobjd look is set.
    /// Not kept across restarts.
    pub following: bool,
}

impl Session {
    /// A fresh session: all off, no objectives, the config's generation settings.
    pub fn new(scene: &Scene, count: u32, clusters: u32, fade_s: f32) -> Session {
        let lights = scene.lights.len();
        Session {
            objectives: Vec::new(),
            next_id: 1,
            key_groups: vec![false; scene.groups.len()],
            locked_groups: vec![false; scene.groups.len()],
            locked_lights: vec![false; lights],
            eos_selection: Vec::new(),
            rules: Rules::new(scene),
            count,
            clusters,
            seed: 0,
            fade_s,
            gallery: None,
            base: Look::off(lights),
            live: Look::off(lights),
            entry: None,
            undo: Vec::new(),
            redo: Vec::new(),
            last_change: None,
            master: 1.0,
            blackout: false,
            looks: BTreeMap::new(),
            following: false,
        }
    }

    /// The seed of the next generate: the seed setting, or a new random one within
    /// 1..=i32::MAX (seeds travel as OSC int32, so a random one can be replayed).
    pub fn next_seed(&self) -> u64 {
        match self.seed {
            0 => rand::random_range(1..=visobjd_method::gallery::MAX_SEED),
            seed => seed,
        }
    }

    /// The sampler's constraints: locked lights include the lights of locked groups, then
    /// the [`Rules`] are added.
    pub fn constraints(&self, scene: &Scene, per_light: bool) -> Constraints {
        let mut locked = self.locked_lights.clone();
        for (g, group) in scene.groups.iter().enumerate() {
            if self.locked_groups[g] {
                for &l in &group.lights {
                    locked[l] = true;
                }
            }
        }
        let mut c = Constraints {
            locked,
            keys: self.key_groups.clone(),
            per_light,
            ..Constraints::none(&visobjd_method::sampler::LightGroups::new(scene))
        };
        self.rules.apply(scene, &mut c);
        c
    }

    /// Refuses a look read for another rig: one made from the scene before a reload that
    /// came between reading it and this change.
    pub fn fits(&self, look: &Look) -> Result<(), Refusal> {
        if look.levels.len() == self.live.levels.len() {
            Ok(())
        } else {
            Err(Refusal::conflict(
                "the scene was reloaded meanwhile: its lights changed; try again",
            ))
        }
    }

    /// Makes `look` both base and live, remembering the old base for undo. A look that is
    /// not the console's (a pick, recall, fader) ends following the console.
    pub fn set_base(&mut self, look: Look, change: Change) {
        let coalesce =
            matches!(change, Change::Fader | Change::Follow) && self.last_change == Some(change);
        if matches!(change, Change::Step | Change::Fader) {
            self.following = false;
        }
        if !coalesce {
            self.undo.push(self.base.clone());
            if self.undo.len() > HISTORY {
                self.undo.remove(0);
            }
        }
        self.redo.clear();
        self.last_change = Some(change);
        self.base = look.clone();
        self.live = look;
    }

    /// Steps back `steps` base looks as one change (the live look goes straight to the
    /// oldest of them); the remaining undo depth, or, when `steps` is 0 or more than there
    /// are, how many there are (nothing changed).
    pub fn undo(&mut self, steps: usize) -> Result<usize, usize> {
        self.walk(true, steps)
    }

    /// Steps forward `steps` base looks again, as [`Session::undo`]; the remaining redo
    /// depth, or how many there are (nothing changed).
    pub fn redo(&mut self, steps: usize) -> Result<usize, usize> {
        self.walk(false, steps)
    }

    /// Moves `steps` base looks from one history stack to the other, back or forward.
    fn walk(&mut self, back: bool, steps: usize) -> Result<usize, usize> {
        let (from, to) = if back {
            (&mut self.undo, &mut self.redo)
        } else {
            (&mut self.redo, &mut self.undo)
        };
        if steps == 0 || steps > from.len() {
            return Err(from.len());
        }
        for next in from.drain(from.len() - steps..).rev() {
            to.push(std::mem::replace(&mut self.base, next));
        }
        let left = from.len();
        self.after_history_step();
        Ok(left)
    }

    fn after_history_step(&mut self) {
        self.live = self.base.clone();
        self.entry = None;
        self.following = false;
        self.last_change = Some(Change::Step);
    }

    /// The undo and redo stacks (oldest first) and what the last base change came from:
    /// what a backup takes with its main's state, so undo, redo and fader coalescing go
    /// on there as on the main.
    pub fn history(&self) -> (&[Look], &[Look], Option<Change>) {
        (&self.undo, &self.redo, self.last_change)
    }

    /// Replaces the history with a main's (see [`Session::history`]); at most [`HISTORY`]
    /// undo steps are kept, the newest.
    pub fn set_history(&mut self, mut undo: Vec<Look>, mut redo: Vec<Look>, last: Option<Change>) {
        undo.drain(..undo.len().saturating_sub(HISTORY));
        redo.drain(..redo.len().saturating_sub(HISTORY));
        self.undo = undo;
        self.redo = redo;
        self.last_change = last;
    }

    /// The objective with `id`, as an index.
    pub fn objective_index(&self, id: u32) -> Option<usize> {
        self.objectives.iter().position(|e| e.id == id)
    }

    /// The look of entry `k`, member `m` of the gallery (both 1-based), or why there is
    /// none.
    pub fn gallery_look(&self, k: usize, m: usize) -> Result<Look, Refusal> {
        let g = self
            .gallery
            .as_ref()
            .ok_or_else(|| Refusal::conflict("there is no gallery yet: send /vo/generate first"))?;
        if k == 0 || k > g.len() {
            return Err(Refusal::conflict(format!(
                "entry {k} is not in the gallery (entries 1-{})",
                g.len()
            )));
        }
        g.candidate(k, m).cloned().ok_or_else(|| {
            Refusal::conflict(format!(
                "entry {k} has no member {m} (members 1-{})",
                g.generation.entries[k - 1].len()
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> Scene {
        let toml = "[[light]]\nchannel = 1\nbasis = \"a.exr\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = 1\n";
        Scene::parse(std::path::Path::new("."), toml).unwrap()
    }

    fn look(v: f32) -> Look {
        let mut l = Look::off(1);
        l.levels[0].intensity = v;
        l
    }

    #[test]
    fn undo_redo_walk_the_base_history() {
        let mut s = Session::new(&scene(), 100, 12, 2.0);
        s.set_base(look(0.1), Change::Step);
        s.set_base(look(0.2), Change::Step);
        assert_eq!(s.undo(1), Ok(1));
        assert_eq!(s.base, look(0.1));
        assert_eq!(s.live, look(0.1));
        assert_eq!(s.redo(1), Ok(0));
        assert_eq!(s.base, look(0.2));
        assert_eq!(s.redo(1), Err(0));
        assert_eq!(s.undo(1), Ok(1));
        assert_eq!(s.undo(1), Ok(0));
        assert_eq!(s.base, look(0.0));
        assert_eq!(s.undo(1), Err(0));
    }

    #[test]
    fn several_steps_are_one_walk_and_too_many_change_nothing() {
        let mut s = Session::new(&scene(), 100, 12, 2.0);
        for i in 1..=4 {
            s.set_base(look(i as f32 / 10.0), Change::Step);
        }
        s.entry = Some((2, 1));
        let before = (s.base.clone(), s.history().0.to_vec());
        assert_eq!(s.undo(0), Err(4));
        assert_eq!(s.undo(5), Err(4));
        assert_eq!(s.redo(1), Err(0));
        assert_eq!((s.base.clone(), s.history().0.to_vec()), before);
        assert_eq!(s.entry, Some((2, 1)), "a refused walk changes nothing");
        assert_eq!(s.undo(3), Ok(1));
        assert_eq!((s.base.clone(), s.live.clone()), (look(0.1), look(0.1)));
        assert_eq!(s.entry, None);
        // The steps walked over are redone one at a time, nearest first, or together.
        assert_eq!(s.redo(1), Ok(2));
        assert_eq!(s.base, look(0.2));
        assert_eq!(s.redo(2), Ok(0));
        assert_eq!(s.base, look(0.4));
        assert_eq!(s.undo(4), Ok(0));
        assert_eq!(s.base, look(0.0));
    }

    #[test]
    fn following_stops_at_a_visobjd_look_and_its_changes_are_one_step() {
        let mut s = Session::new(&scene(), 100, 12, 2.0);
        s.set_base(look(0.1), Change::Grab);
        s.following = true;
        for i in 2..6 {
            s.set_base(look(i as f32 / 10.0), Change::Follow);
        }
        assert!(s.following);
        assert_eq!(s.undo(1), Ok(1), "the followed changes are one step");
        assert_eq!(s.base, look(0.1));
        assert!(!s.following, "an undo is a visobjd look");
        s.following = true;
        s.set_base(look(0.2), Change::Grab);
        assert!(s.following, "a grab keeps following");
        s.set_base(look(0.3), Change::Fader);
        assert!(!s.following);
        s.following = true;
        s.set_base(look(0.4), Change::Step);
        assert!(!s.following);
    }

    #[test]
    fn fader_moves_coalesce_and_history_is_bounded() {
        let mut s = Session::new(&scene(), 100, 12, 2.0);
        for i in 0..10 {
            s.set_base(look(i as f32 / 10.0), Change::Fader);
        }
        assert_eq!(s.undo(1), Ok(0), "one step for a fader move");
        for i in 0..200 {
            s.set_base(look(i as f32 / 200.0), Change::Step);
        }
        let mut depth = 0;
        while s.undo(1).is_ok() {
            depth += 1;
        }
        assert_eq!(depth, HISTORY);
    }
}
