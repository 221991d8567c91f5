//! The shipped TouchOSC layout against the daemon and the docs, both ways: every address
//! the layout sends is one the real daemon knows (and takes with the layout's arguments:
//! the demo's movers end at the last palette button pressed),
//! every address it listens to is a documented push, and every address of docs/osc.md is
//! on the tablet unless docs/touchosc.md says it is not.

use std::io::Read;
use std::path::Path;
use std::process::Command;

use crate::common;
use crate::common::bin;
use crate::common::daemon::{Daemon, GENERATE_PATIENCE, Osc, Setup, int, string};
use rosc::OscType;
use visobjd_testkit::temp_dir;

/// One `<osc>` message of the layout.
#[derive(Debug)]
struct Message {
    control: String,
    path: String,
    send: bool,
    receive: bool,
    /// (value, condition) pairs that send it.
    triggers: Vec<(String, String)>,
    args: Vec<OscType>,
}

/// Inflates a .tosc file and parses its messages; VALUE arguments are sent at the low end
/// of their scale.
fn messages(tosc: &[u8]) -> (String, Vec<Message>) {
    let mut xml = String::new();
    flate2::read::ZlibDecoder::new(tosc)
        .read_to_string(&mut xml)
        .expect("a .tosc is zlib-compressed UTF-8");
    let doc = roxmltree::Document::parse(&xml).expect("the layout is well-formed XML");
    let root = doc.root_element();
    assert_eq!(root.tag_name().name(), "lexml");
    assert_eq!(root.attribute("version"), Some("3"));
    let top = root.first_element_child().expect("a root node");
    assert_eq!(
        (top.tag_name().name(), top.attribute("type")),
        ("node", Some("GROUP"))
    );
    let mut out = Vec::new();
    for osc in doc.descendants().filter(|n| n.has_tag_name("osc")) {
        let node = osc
            .ancestors()
            .find(|a| a.has_tag_name("node"))
            .expect("a message belongs to a node");
        let control = node
            .descendants()
            .find(|p| p.has_tag_name("property") && text(*p, "key") == "name")
            .map(|p| text(p, "value"))
            .unwrap_or_default();
        let partials = |tag: &str| -> Vec<roxmltree::Node> {
            child(osc, tag)
                .map(|c| c.children().filter(|p| p.has_tag_name("partial")).collect())
                .unwrap_or_default()
        };
        let path: String = partials("path")
            .iter()
            .map(|p| {
                assert_eq!(text(*p, "type"), "CONSTANT", "{control}: a constant path");
                text(*p, "value")
            })
            .collect();
        let args = partials("arguments")
            .iter()
            .map(|p| {
                let value = match text(*p, "type").as_str() {
                    "CONSTANT" => text(*p, "value"),
                    "VALUE" => text(*p, "scaleMin"),
                    other => panic!("{control}: argument type {other}"),
                };
                match text(*p, "conversion").as_str() {
                    "STRING" => OscType::String(value),
                    "INTEGER" => OscType::Int(value.parse::<f32>().expect("a number") as i32),
                    "FLOAT" => OscType::Float(value.parse().expect("a number")),
                    other => panic!("{control}: conversion {other}"),
                }
            })
            .collect();
        out.push(Message {
            control,
            path,
            send: text(osc, "send") == "1",
            receive: text(osc, "receive") == "1",
            triggers: child(osc, "triggers")
                .map(|t| {
                    t.children()
                        .filter(|c| c.has_tag_name("trigger"))
                        .map(|c| (text(c, "var"), text(c, "condition")))
                        .collect()
                })
                .unwrap_or_default(),
            args,
        });
    }
    (xml, out)
}

/// The first child element of `n` called `tag`.
fn child<'a, 'i>(n: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(tag))
}

/// The text of `n`'s child `tag` ("" if none).
fn text(n: roxmltree::Node, tag: &str) -> String {
    child(n, tag)
        .and_then(|c| c.text())
        .unwrap_or_default()
        .to_string()
}

/// The caption (its label's text) of button `control` in the layout's XML.
fn caption(xml: &str, control: &str) -> String {
    let doc = roxmltree::Document::parse(xml).expect("the layout is well-formed XML");
    let name = format!("{control}_caption");
    let node = doc
        .descendants()
        .filter(|n| n.has_tag_name("node"))
        .find(|n| {
            child(*n, "properties").is_some_and(|ps| {
                ps.children()
                    .any(|p| text(p, "key") == "name" && text(p, "value") == name)
            })
        })
        .unwrap_or_else(|| panic!("no caption of {control}"));
    child(node, "values")
        .and_then(|vs| vs.children().find(|v| text(*v, "key") == "text"))
        .map(|v| text(v, "default"))
        .unwrap_or_else(|| panic!("{control}'s caption has no text"))
}

/// The shipped layout.
fn shipped() -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("touchosc/visobjd.tosc"))
        .expect("touchosc/visobjd.tosc is in the repository")
}

/// The address without trailing numeric segments (they are arguments, docs/osc.md).
fn stem(path: &str) -> String {
    let mut segs: Vec<&str> = path.split('/').filter(|s| !s.is_empty()).collect();
    while segs.last().is_some_and(|s| s.parse::<f64>().is_ok()) {
        segs.pop();
    }
    format!("/{}", segs.join("/"))
}

/// Whether a docs pattern (`<id>` stands for any one segment) names `path`.
fn names(pattern: &str, path: &str) -> bool {
    let p: Vec<&str> = pattern.split('/').collect();
    let a: Vec<&str> = path.split('/').collect();
    p.len() == a.len()
        && p.iter()
            .zip(&a)
            .all(|(p, a)| (p.starts_with('<') && p.ends_with('>')) || p.eq_ignore_ascii_case(a))
}

/// Backticked addresses of the first column of the table rows in `text`; `/x` after a full
/// address replaces its last segment (`/vo/generate/count`, `/clusters`).
fn table_addresses(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines().filter(|l| l.starts_with("| `")) {
        let first = line.split(" | ").next().unwrap_or_default();
        let mut last_full = String::new();
        for tick in first.split('`').skip(1).step_by(2) {
            if tick.starts_with("/vo") {
                last_full = tick.to_string();
                out.push(last_full.clone());
            } else if let Some((parent, _)) = last_full.rsplit_once('/')
                && tick.starts_with('/')
            {
                out.push(format!("{parent}{tick}"));
            }
        }
    }
    out
}

/// A page's text between the heading `from` and the next heading of its level or above.
fn section<'a>(page: &'a str, from: &str) -> &'a str {
    let start = page
        .find(from)
        .unwrap_or_else(|| panic!("the page has {from}"));
    let level = from.chars().take_while(|&c| c == '#').count();
    let rest = &page[start + from.len()..];
    let end = rest
        .match_indices("\n#")
        .find(|(i, _)| {
            let hashes = rest[i + 1..].chars().take_while(|&c| c == '#').count();
            hashes <= level
        })
        .map_or(rest.len(), |(i, _)| i);
    &rest[..end]
}

/// A page of the reference, `docs/<name>`.
fn doc(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("docs")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn the_shipped_layout_is_what_the_generator_writes() {
    let dir = temp_dir("touchosc-regenerate");
    let out = dir.join("visobjd.tosc");
    let refs = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/demo/refs");
    let run = Command::new(bin())
        .args(["touchosc", "--refs"])
        .arg(&refs)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("visobjd runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let (fresh, _) = messages(&std::fs::read(&out).expect("written"));
    let (committed, _) = messages(&shipped());
    assert!(
        fresh == committed,
        "touchosc/visobjd.tosc is stale: regenerate it with \
         `cargo run --release -- touchosc --out touchosc/visobjd.tosc`"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_layout_has_its_pages_and_their_controls() {
    let (xml, msgs) = messages(&shipped());
    for page in [
        "Objectives",
        "Gallery",
        "Constraints",
        "Transfer",
        "Looks",
        "Positions",
    ] {
        assert!(xml.contains(&format!("<![CDATA[{page}]]>")), "page {page}");
    }
    let sends = |path: &str| {
        msgs.iter()
            .filter(|m| m.send && m.path == path)
            .collect::<Vec<_>>()
    };
    // A button per shipped reference image.
    let refs = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/demo/refs");
    let images = std::fs::read_dir(refs).expect("demo refs").count();
    assert_eq!(sends("/vo/objective/add").len(), images);
    assert_eq!(sends("/vo/objective/last/aspects").len(), 3);
    let region = sends("/vo/objective/last/region");
    assert_eq!(region[0].args.len(), 4);
    // The region pad explores while touched: 1 on touch-down, 0 on release, and sends the
    // region whichever axis moves.
    let explore = sends("/vo/explore");
    assert_eq!(explore.len(), 1, "{explore:?}");
    assert_eq!(explore[0].control, region[0].control);
    assert_eq!(
        explore[0].triggers,
        [("touch".to_string(), "ANY".to_string())]
    );
    for axis in ["x", "y"] {
        assert!(
            region[0]
                .triggers
                .contains(&(axis.to_string(), "ANY".to_string())),
            "{:?}",
            region[0].triggers
        );
    }
    // The demo's groups: exclusions, saturation and ratios, transfers; pins.
    let demo =
        visobjd_scene::Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/demo"))
            .expect("the demo scene");
    let first = demo.groups[0].name.clone();
    assert!(first.contains(' '), "`{first}`: the case this checks");
    // OSC 1.0 forbids spaces in an address: the layout writes them `_`.
    let at = first.replace(' ', "_");
    assert_eq!(sends(&format!("/vo/group/{at}/exclude")).len(), 3);
    assert_eq!(sends(&format!("/vo/group/{at}/saturation")).len(), 1);
    for m in &msgs {
        assert!(
            m.path
                .chars()
                .all(|c| c.is_ascii_graphic() && !"#*,?[]{}".contains(c)),
            "`{}` is not an OSC 1.0 address",
            m.path
        );
    }
    assert!(
        msgs.iter()
            .filter(|m| m.path.ends_with("/ratio"))
            .all(|m| m.args[0] == OscType::String(first.clone()))
    );
    assert!(msgs.iter().any(|m| m.path.ends_with("/ratio")));
    assert_eq!(sends("/vo/pin/add").len(), 5);
    let transfers = sends("/vo/transfer");
    assert!(
        transfers
            .iter()
            .any(|m| m.args[1] == OscType::String("group".into()))
    );
    assert!(
        transfers
            .iter()
            .any(|m| m.args[1] == OscType::String("region".into()))
    );
    // Entries 1-12, each lit by its own push; looks 1-16 both ways.
    let picks: Vec<&OscType> = sends("/vo/pick").iter().map(|m| &m.args[0]).collect();
    assert_eq!(
        picks,
        (1..=12)
            .map(OscType::Int)
            .collect::<Vec<_>>()
            .iter()
            .collect::<Vec<_>>()
    );
    for k in 1..=12 {
        let lit = format!("/vo/entry/{k}/lit");
        assert!(
            msgs.iter().any(|m| m.receive
                && !m.send
                && m.path == lit
                && m.control == format!("entry_{k}")),
            "{lit} lights entry_{k}"
        );
    }
    assert_eq!(sends("/vo/look/save").len(), 16);
    assert_eq!(sends("/vo/look/recall").len(), 16);
    // The demo's movers (its last group, past the constraints page's room): a button per
    // palette they share, in number order, captioned with its name.
    let movers: Vec<(String, Vec<OscType>)> = sends("/vo/group/movers/position")
        .iter()
        .map(|m| (caption(&xml, &m.control), m.args.clone()))
        .collect();
    let want: Vec<(String, Vec<OscType>)> = demo
        .palettes
        .iter()
        .map(|p| (p.name.clone().expect("named"), vec![int(p.number as i32)]))
        .collect();
    assert_eq!(want.len(), 5, "the demo's five palettes");
    assert_eq!(movers, want);
    assert_eq!(want[0].0, "DS left");
    for path in [
        "/vo/generate",
        "/vo/next",
        "/vo/prev",
        "/vo/undo",
        "/vo/redo",
        "/vo/fade",
        "/vo/master",
        "/vo/blackout",
        "/vo/subscribe",
    ] {
        assert_eq!(sends(path).len(), 1, "{path}");
    }
}

#[test]
fn every_layout_address_is_one_the_daemon_takes() {
    let (_, msgs) = messages(&shipped());
    // The shipped layout is made for the demo: its groups' rows (constraints, transfer) name
    // the demo's groups, so the daemon runs the demo scene.
    let mut d = Daemon::start_setup(
        "touchosc-addresses",
        Setup {
            scene_from: Some(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/demo")),
            ..Setup::default()
        },
    );
    // The layout's image buttons name the demo's references.
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/demo/refs");
    for e in std::fs::read_dir(&demo)
        .expect("demo refs")
        .filter_map(Result::ok)
    {
        std::fs::copy(e.path(), d.refs().join(e.file_name())).expect("copy a reference");
    }
    d.ok(
        "/vo/generate/clusters",
        vec![int(12)],
        "/vo/generate/clusters",
    );
    d.add_objective("warm.png", "both");
    d.generate();
    let mut failed = Vec::new();
    // In layout order, but clearing the objectives last (a generate needs one).
    let clear = |m: &&Message| m.path == "/vo/objective/clear";
    let sends = msgs.iter().filter(|m| m.send);
    for m in sends
        .clone()
        .filter(|m| !clear(m))
        .chain(sends.filter(clear))
    {
        d.send(&m.path, m.args.clone());
        // Whatever comes back before the fence's pong (a generate's /vo/generated may come
        // later, and is taken by a later fence).
        let mut replies = d.fence();
        if m.path == "/vo/generate"
            && !replies
                .iter()
                .any(|r| r.addr == "/vo/generated" || r.addr == "/vo/error")
        {
            replies.extend(d.collect("/vo/generated", GENERATE_PATIENCE, "the generate button"));
        }
        for reply in replies {
            if reply.addr != "/vo/error" {
                continue;
            }
            let sentence = format!("{:?}", reply.args);
            let mine = matches!(&reply.args[0], OscType::String(a) if stem(a).eq_ignore_ascii_case(&stem(&m.path)));
            // Refused for the state it found (entry 12 of a smaller gallery, a generate
            // still running) is fine; not knowing the address, its arguments or the group
            // or light it names is not.
            if !mine
                || sentence.contains("unknown address")
                || sentence.contains("not in the scene")
                || sentence.contains("expected")
                || sentence.contains("must be")
            {
                failed.push(format!(
                    "{} {:?} ({}): {sentence}",
                    m.path, m.args, m.control
                ));
            }
        }
    }
    assert!(failed.is_empty(), "refused:\n{}", failed.join("\n"));
    // The last palette button pressed (the positions page's, palette 5) moved every mover.
    let (_, positions) = d.live_aimed();
    assert_eq!(
        positions,
        (45..=50).map(|ch| (ch, 5)).collect::<Vec<_>>(),
        "the movers at the last palette pressed"
    );
    // The buttons did what they say: entries exist, looks were saved.
    d.ok("/vo/unsubscribe", vec![], "/vo/unsubscribed");
    assert_eq!(d.looks().len(), 16);
    let entries = d.gallery().len();
    assert!((1..=12).contains(&entries), "{entries} entries");
}

#[test]
fn the_osc_reference_and_the_layout_agree_both_ways() {
    let osc = doc("osc.md");
    // The command tables: every table of the Addresses section.
    let commands = table_addresses(section(&osc, "## Addresses"));
    assert!(commands.len() > 30, "{commands:?}");
    let pushes = table_addresses(section(&osc, "## Pushed to subscribers"));
    assert!(
        pushes.contains(&"/vo/entry/<k>/lit".to_string()),
        "{pushes:?}"
    );
    let tablet = doc("touchosc.md");
    let excluded: Vec<String> = tablet
        .lines()
        .find(|l| l.starts_with("Not on the tablet"))
        .expect("docs/touchosc.md says which addresses are not on the tablet")
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|a| a.starts_with("/vo"))
        .map(str::to_string)
        .collect();
    let (_, msgs) = messages(&shipped());

    for c in &commands {
        let on_tablet = msgs.iter().any(|m| m.send && names(c, &stem(&m.path)));
        let left_out = excluded.contains(c);
        assert!(
            on_tablet != left_out,
            "{c}: {}",
            if on_tablet {
                "on the tablet but listed as not"
            } else {
                "neither on the tablet nor listed as left out"
            }
        );
    }
    for x in &excluded {
        assert!(commands.contains(x), "{x} is not in the OSC reference");
    }
    for m in &msgs {
        if m.send {
            assert!(
                commands.iter().any(|c| names(c, &stem(&m.path))),
                "{} sends {}, which is not in the OSC reference",
                m.control,
                m.path
            );
        }
        if m.receive {
            assert!(
                pushes.iter().any(|p| names(p, &m.path)),
                "{} listens to {}, which is not a documented push",
                m.control,
                m.path
            );
        }
    }
}

#[test]
fn feedback_pushes_light_the_live_entry_and_describe_the_state() {
    let mut d = Daemon::start("touchosc-feedback");
    let mut tablet = d.client();
    // The state comes with the subscription (pushed before the reply).
    let mut dump = tablet.call("/vo/subscribe", vec![], "/vo/subscribed");
    dump.extend(tablet.fence());
    assert!(dump.iter().any(|m| m.addr == "/vo/status/text"), "{dump:?}");
    d.add_objective("warm.png", "both");
    d.generate();
    let n = d.gallery().len();
    assert!(n >= 2, "a gallery of {n}");
    tablet.fence();
    d.ok("/vo/pick", vec![int(2)], "/vo/picked");
    let got = tablet.fence();
    let lit = |k: usize| {
        got.iter()
            .rev()
            .find(|m| m.addr == format!("/vo/entry/{k}/lit"))
            .map(|m| m.args.clone())
    };
    assert_eq!(lit(2), Some(vec![int(1)]), "{got:?}");
    assert_eq!(lit(1), Some(vec![int(0)]), "{got:?}");
    assert_eq!(lit(n), Some(vec![int(i32::from(n == 2))]), "{got:?}");
    let text = got
        .iter()
        .rev()
        .find(|m| m.addr == "/vo/status/text")
        .expect("a status line");
    assert!(
        matches!(&text.args[..], [OscType::String(s)] if s.contains(&format!("entry 2 of {n} live"))),
        "{text:?}"
    );
    // Another tablet's fader follows: the value itself is pushed.
    d.ok("/vo/master", vec![common::daemon::float(0.5)], "/vo/master");
    assert!(tablet.fence().iter().any(|m| m.addr == "/vo/master"));
    // The newest objective is `last`.
    let r = d.ok(
        "/vo/objective/last/aspects",
        vec![string("color")],
        "/vo/objective/aspects",
    );
    assert_eq!(r.args, vec![int(1), string("color")]);
    d.ok("/vo/objective/clear", vec![], "/vo/objective/cleared");
    d.refused("/vo/objective/last/region", vec![]);
}

#[test]
fn the_generator_names_the_references_a_page_has_no_room_for() {
    let dir = temp_dir("touchosc-left-off");
    let refs = dir.join("refs");
    std::fs::create_dir_all(&refs).expect("mkdir");
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/demo/refs");
    let one = std::fs::read_dir(&demo)
        .expect("demo refs")
        .map(|e| e.expect("entry").path())
        .find(|p| p.extension().is_some_and(|e| e == "png"))
        .expect("a PNG");
    let names: Vec<String> = (1..=14).map(|i| format!("ref{i:02}.png")).collect();
    for n in &names {
        std::fs::copy(&one, refs.join(n)).expect("copy");
    }
    let run = Command::new(bin())
        .args(["touchosc", "--refs"])
        .arg(&refs)
        .arg("--out")
        .arg(dir.join("t.tosc"))
        .output()
        .expect("visobjd runs");
    assert!(run.status.success(), "{run:?}");
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("room for 12 references; left off: ref13.png, ref14.png"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(dir);
}
