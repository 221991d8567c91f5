//! The OSC address space (docs/osc.md) as commands: each family of addresses is one file with
//! a `Cmd` enum, its `parse` (syntax: types and ranges) and its `apply` (against the
//! engine: existence, state changes, replies). Adding an address touches its family's
//! file and one arm here at most.
//!
//! A command that fails changes nothing and answers one `/vo/error`.

mod backup;
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
    Backup(backup::Cmd),
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
        if let Some(c) = backup::Cmd::parse(req)? {
            return Ok(Command::Backup(c));
        }
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
            Command::Backup(_) => "backup",
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
            Command::Backup(c) => c.apply(e, peer),
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

impl Command {
    /// Whether the command changes the session (the objectives, constraints, gallery,
    /// looks or stage): such commands are mirrored to a backup, and a backup refuses them
    /// from anyone but its main. Queries, subscriptions, pings and exports do not.
    fn changes_state(&self) -> bool {
        match self {
            Command::Backup(c) => c.changes_state(),
            Command::EosIn(c) => !matches!(c, eos_in::Cmd::Selection | eos_in::Cmd::EosOut(None)),
            Command::Objective(c) => !matches!(
                c,
                objective::Cmd::Edit(objective::Edit::List | objective::Edit::Palette { .. })
            ),
            Command::Constraint(c) => !matches!(c, constraint::Cmd::Pins | constraint::Cmd::List),
            Command::Console(_) | Command::Generate(_) | Command::Transfer(_) => true,
            Command::Gallery(c) => {
                !matches!(c, gallery::Cmd::Candidate { .. } | gallery::Cmd::Gallery)
            }
            Command::Live(c) => !matches!(c, live::Cmd::Live),
            Command::Looks(c) => !matches!(c, looks::Cmd::List),
            Command::Status(_) | Command::TestHook(_) => false,
        }
    }

    /// Whether the command itself is forwarded to backups once accepted. A generate is
    /// forwarded by the engine instead, as the gallery it installs (`/vo/backup/gallery`),
    /// and so are explore galleries (with their regions, src/engine/explore.rs); the
    /// backup's own messages are not forwarded.
    fn forwarded(&self) -> bool {
        self.changes_state()
            && !matches!(
                self,
                Command::Generate(
                    generate::Cmd::Generate | generate::Cmd::Seeded(_) | generate::Cmd::Explore(_)
                ) | Command::Backup(_)
            )
    }
}

pub use console::follow as follow_console;
pub use gallery::sizes as gallery_sizes;

/// Parses and applies one message: its replies, or the sentence for `/vo/error`. A backup
/// answers queries but refuses changes: they come from its main.
pub fn run(e: &Arc<Engine>, req: &Request, peer: &Peer) -> Result<Vec<OscMessage>, String> {
    let command = Command::parse(req)?;
    if let Some(main) = e.main()
        && command.changes_state()
    {
        return Err(format!("this is a backup of {main}; send to the main"));
    }
    apply(e, command, req, peer)
}

/// Parses and applies one message a backup received from its main (src/backup.rs): the
/// same path as [`run`], changes allowed.
pub fn mirror(e: &Arc<Engine>, req: &Request, peer: &Peer) -> Result<Vec<OscMessage>, String> {
    apply(e, Command::parse(req)?, req, peer)
}

/// Applies a parsed command; an accepted change is forwarded to the backups (at its
/// commit, see [`crate::backup::Pending`], or here if no commit took it).
fn apply(
    e: &Arc<Engine>,
    command: Command,
    req: &Request,
    peer: &Peer,
) -> Result<Vec<OscMessage>, String> {
    let forward = command.forwarded().then(|| OscMessage {
        addr: req.path(),
        args: req.args.clone(),
    });
    crate::backup::Pending::set(forward);
    let applied = command.apply(e, peer);
    let left = crate::backup::Pending::take();
    if let (Ok(_), Some(m)) = (&applied, left) {
        e.forward(&m);
    }
    applied
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
