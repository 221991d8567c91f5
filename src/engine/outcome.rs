//! What a change to the session asks of the engine once it is made: the replies, whether
//! the stage shows it, whether it is saved, and whether subscribers hear of it. Commands
//! describe their change with an [`Outcome`]; [`super::Engine::commit`] carries it out, in
//! one place and one order, for every command.

use rosc::OscMessage;

/// How the output follows a change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Show {
    /// The output is not touched.
    Nothing,
    /// The live look goes out, crossfading over this many seconds.
    Look(f32),
    /// Master and blackout go out at once.
    Master,
}

/// Whether (and how) a change is written to the state folder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Persist {
    /// Not at all (a query, or state that is not kept).
    No,
    /// Queued; the reply does not wait (fader moves: a flood costs one write per moment).
    Later,
    /// Written before the reply goes out, and a failed write is answered with `/vo/error`.
    Now,
}

/// Who else hears of a change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Push {
    /// Nobody.
    Nobody,
    /// Subscribers get the tablet feedback (status, entry lights, ...).
    Feedback,
    /// Subscribers get the replies too, then the feedback (another tablet's fader follows).
    Echo,
}

/// A command's description of its change, built from its replies:
/// `Outcome::reply(m).show_look(fade).saved().pushed()`.
#[derive(Debug, Clone)]
#[must_use = "an outcome does nothing until the engine commits it"]
pub struct Outcome {
    pub(super) replies: Vec<OscMessage>,
    pub(super) show: Show,
    pub(super) persist: Persist,
    pub(super) push: Push,
}

impl Outcome {
    /// Answers with these messages and changes nothing else (a query).
    pub fn replies(replies: Vec<OscMessage>) -> Outcome {
        Outcome {
            replies,
            show: Show::Nothing,
            persist: Persist::No,
            push: Push::Nobody,
        }
    }

    /// Answers with one message.
    pub fn reply(reply: OscMessage) -> Outcome {
        Outcome::replies(vec![reply])
    }

    /// The live look goes to the stage with a crossfade of `fade_s` seconds.
    pub fn show_look(mut self, fade_s: f32) -> Outcome {
        self.show = Show::Look(fade_s);
        self
    }

    /// Master and blackout go to the stage at once.
    pub fn show_master(mut self) -> Outcome {
        self.show = Show::Master;
        self
    }

    /// Written to the state folder before the reply (a restart must not lose it).
    pub fn saved(mut self) -> Outcome {
        self.persist = Persist::Now;
        self
    }

    /// Written to the state folder soon, without holding up the reply.
    pub fn saved_later(mut self) -> Outcome {
        self.persist = Persist::Later;
        self
    }

    /// Subscribers get the feedback of the new state.
    pub fn pushed(mut self) -> Outcome {
        self.push = Push::Feedback;
        self
    }

    /// Subscribers get the replies as well as the feedback.
    pub fn echoed(mut self) -> Outcome {
        self.push = Push::Echo;
        self
    }
}
