//! The OSC address space (docs/osc.md) as commands: each family of addresses is one file with
//! a `Cmd` enum, its `parse` (syntax: types and ranges) and its `apply` (against the
//! engine: existence, state changes, replies). Adding an address touches its family's
//! file and one arm here at most.
//!
//! A command that fails changes nothing and answers one `/vo/error`.

mod console;
mod constraint;
mod eos_in;
mod gallery;
mod generate;
mod live;
mod looks;
mod objective;
mod status;
mod test_hook;
mod transfer;

use std::sync::Arc;

use rosc::{OscMessage, OscType};

use crate::engine::Engine;
use crate::osc::Peer;
use crate::osc::args::{self, Request};
use crate::osc::packet::{self, Item, PacketError};
use visobjd_scene::Scene;
use visobjd_scene::look::Look;

/// Every command the daemon understands.
enum Command {
    EosIn(eos_in::Cmd),
    Objective(objective::Cmd),
    Constraint(constraint::Cmd),
    Console(console::Cmd),
    Generate(generate::Cmd),
    Gallery(gallery::Cmd),
    Live(live::Cmd),
    Looks(looks::Cmd),
    Status(status::Cmd),
    TestHook(test_hook::Cmd),
    Transfer(transfer::Cmd),
}

impl Command {
    fn parse(req: &Request) -> Result<Command, String> {
        if let Some(c) = eos_in::Cmd::parse(req)? {
            return Ok(Command::EosIn(c));
        }
        if let Some(c) = objective::Cmd::parse(req)? {
            return Ok(Command::Objective(c));
        }
        if let Some(c) = constraint::Cmd::parse(req)? {
            return Ok(Command::Constraint(c));
        }
        if let Some(c) = console::Cmd::parse(req)? {
            return Ok(Command::Console(c));
        }
        if let Some(c) = generate::Cmd::parse(req)? {
            return Ok(Command::Generate(c));
        }
        if let Some(c) = gallery::Cmd::parse(req)? {
            return Ok(Command::Gallery(c));
        }
        if let Some(c) = live::Cmd::parse(req)? {
            return Ok(Command::Live(c));
        }
        if let Some(c) = looks::Cmd::parse(req)? {
            return Ok(Command::Looks(c));
        }
        if let Some(c) = status::Cmd::parse(req)? {
            return Ok(Command::Status(c));
        }
        if let Some(c) = test_hook::Cmd::parse(req)? {
            return Ok(Command::TestHook(c));
        }
        if let Some(c) = transfer::Cmd::parse(req)? {
            return Ok(Command::Transfer(c));
        }
        Err(format!(
            "unknown address {}: the addresses are listed in the README's OSC reference",
            req.path()
        ))
    }

    /// The address family, for [`parse`]'s callers.
    fn family(&self) -> &'static str {
        match self {
            Command::EosIn(_) => "eos",
            Command::Objective(_) => "objective",
            Command::Constraint(_) => "constraint",
            Command::Console(_) => "console",
            Command::Generate(_) => "generate",
            Command::Gallery(_) => "gallery",
            Command::Live(_) => "live",
            Command::Looks(_) => "looks",
            Command::Status(_) => "status",
            Command::TestHook(_) => "test",
            Command::Transfer(_) => "transfer",
        }
    }

    fn apply(self, e: &Arc<Engine>, peer: &Peer) -> Result<Vec<OscMessage>, String> {
        match self {
            Command::EosIn(c) => c.apply(e),
            Command::Objective(c) => c.apply(e),
            Command::Constraint(c) => c.apply(e),
            Command::Console(c) => c.apply(e),
            Command::Generate(c) => c.apply(e, peer),
            Command::Gallery(c) => c.apply(e),
            Command::Live(c) => c.apply(e),
            Command::Looks(c) => c.apply(e),
            Command::Status(c) => c.apply(e, peer),
            Command::TestHook(c) => c.apply(e),
            Command::Transfer(c) => c.apply(e),
        }
    }
}

pub use console::follow as follow_console;
pub use gallery::sizes as gallery_sizes;

/// Parses and applies one message: its replies, or the sentence for `/vo/error`.
pub fn run(e: &Arc<Engine>, req: &Request, peer: &Peer) -> Result<Vec<OscMessage>, String> {
    Command::parse(req)?.apply(e, peer)
}

/// Reads one received packet (a datagram or a stream frame) the way the daemon does, up to
/// the commands and without an engine: for each message the server would hand on, the
/// command family it names or the sentence of its `/vo/error`. A pure function, so the
/// fuzz targets (fuzz/) and tests can drive the whole parsing path with arbitrary bytes.
pub fn parse(bytes: &[u8]) -> Result<Vec<Result<&'static str, String>>, PacketError> {
    Ok(packet::decode_items(bytes)?
        .into_iter()
        .filter_map(|item| match item {
            Item::Message(m) => {
                let req = Request::new(m);
                (!req.is_button_release()).then(|| Command::parse(&req).map(|c| c.family()))
            }
            Item::Malformed { why, .. } => Some(Err(why)),
        })
        .collect())
}

/// Argument `i` as a whole number in `min..=max`.
fn int_arg(req: &Request, i: usize, what: &str, min: i64, max: i64) -> Result<i64, String> {
    let v = args::integer(args::required(&req.args, i, what)?, what)?;
    if !(min..=max).contains(&v) {
        return Err(format!("{what} must be {min}..={max}, got {v}"));
    }
    Ok(v)
}

/// Optional argument `i` as a whole number in `min..=max`, or `default`.
fn opt_int_arg(
    req: &Request,
    i: usize,
    what: &str,
    min: i64,
    max: i64,
    default: i64,
) -> Result<i64, String> {
    if req.args.len() > i {
        int_arg(req, i, what, min, max)
    } else {
        Ok(default)
    }
}

/// Argument `i` as a number in `min..=max`.
fn num_arg(req: &Request, i: usize, what: &str, min: f64, max: f64) -> Result<f32, String> {
    args::number_in(args::required(&req.args, i, what)?, what, min, max).map(|v| v as f32)
}

/// Arguments `i..i+3` as an sRGB colour, each 0..1.
fn rgb_args(req: &Request, i: usize) -> Result<[f32; 3], String> {
    Ok([
        num_arg(req, i, "red", 0.0, 1.0)?,
        num_arg(req, i + 1, "green", 0.0, 1.0)?,
        num_arg(req, i + 2, "blue", 0.0, 1.0)?,
    ])
}

/// Argument 0 as a 0/1 switch.
fn switch_arg(req: &Request, what: &str) -> Result<bool, String> {
    args::switch(args::required(&req.args, 0, what)?, what)
}

/// The light with channel `segment`, as an index.
fn light(scene: &Scene, segment: &str) -> Result<usize, String> {
    segment
        .parse::<u32>()
        .ok()
        .and_then(|ch| scene.light_index(ch))
        .ok_or_else(|| {
            format!(
                "light {segment} is not in the scene ({})",
                scene.channel_range()
            )
        })
}

/// The group called `name` (case-insensitive), as an index.
fn group(scene: &Scene, name: &str) -> Result<usize, String> {
    scene.group_index(name).ok_or_else(|| {
        format!(
            "group `{name}` is not in the scene (groups: {})",
            scene
                .groups
                .iter()
                .map(|g| g.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    })
}

/// `ch intensity r g b` for every light of `look`, in channel order.
fn light_args(scene: &Scene, look: &Look) -> Vec<OscType> {
    scene
        .lights
        .iter()
        .zip(&look.levels)
        .flat_map(|(light, lv)| one_light(light.channel, lv))
        .collect()
}

fn one_light(channel: u32, lv: &visobjd_scene::look::Level) -> [OscType; 5] {
    [
        OscType::Int(channel as i32),
        OscType::Float(lv.intensity),
        OscType::Float(lv.color[0]),
        OscType::Float(lv.color[1]),
        OscType::Float(lv.color[2]),
    ]
}

fn int(v: usize) -> OscType {
    OscType::Int(v as i32)
}

fn text(s: &str) -> OscType {
    OscType::String(s.to_string())
}
