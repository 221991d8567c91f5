//! Why a command changed nothing: a sentence a person can act on, and what kind of mistake
//! it is, so each transport answers in its own terms (OSC renders `/vo/error`, the web page
//! an HTTP status) without reading the sentence. The sentence is the protocol; the kind is
//! for whoever must tell "fix your message" from "not now" from "not your fault".

use std::fmt;

/// What kind of mistake a [`Refusal`] is (docs/osc.md, "Errors").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefusalKind {
    /// The message itself is wrong: an unknown address, a missing or mistyped argument, a
    /// value out of range, a name or path that is not allowed. Sent again as it is, it
    /// fails again.
    Input,
    /// Well formed, but the state does not allow it: no such entry, light, objective or
    /// look, no gallery yet, a generate running, a backup taking changes only from its main.
    Conflict,
    /// Something inside failed (the disk, a thread, an encoding): the sender did nothing
    /// wrong, and the daemon's log says more.
    Internal,
}

/// A command's refusal: nothing changed, and this says why.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    /// What kind of mistake it is.
    pub kind: RefusalKind,
    /// The sentence answered (`/vo/error <address> <sentence>`, `{"error": sentence}`).
    pub sentence: String,
}

impl Refusal {
    /// The message is wrong ([`RefusalKind::Input`]).
    pub fn input(sentence: impl Into<String>) -> Refusal {
        Refusal::new(RefusalKind::Input, sentence)
    }

    /// The state does not allow it ([`RefusalKind::Conflict`]).
    pub fn conflict(sentence: impl Into<String>) -> Refusal {
        Refusal::new(RefusalKind::Conflict, sentence)
    }

    /// Something inside failed ([`RefusalKind::Internal`]).
    pub fn internal(sentence: impl Into<String>) -> Refusal {
        Refusal::new(RefusalKind::Internal, sentence)
    }

    fn new(kind: RefusalKind, sentence: impl Into<String>) -> Refusal {
        Refusal {
            kind,
            sentence: sentence.into(),
        }
    }

    /// The same refusal, its sentence after `what`: `look 3 was not saved: <sentence>`.
    pub fn after(self, what: &str) -> Refusal {
        Refusal {
            sentence: format!("{what}: {}", self.sentence),
            ..self
        }
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.sentence)
    }
}
