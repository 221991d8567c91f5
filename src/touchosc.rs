//! The booth tablet's TouchOSC (Mk2) layout, generated from the address space so that it is
//! regenerated, never hand-edited, when addresses change: `visobjd touchosc --out FILE`.
//!
//! A `.tosc` file is zlib-compressed XML: `<lexml version='3'>` holding one root `GROUP`
//! node; every node has `<properties>` (name, frame, colour, ...), `<values>` (`x`, `touch`,
//! a label's `text`), `<messages>` (`<osc>` with triggers, a path and arguments made of
//! `<partial>`s) and `<children>`. Five pages: objectives (with the drag-to-explore pad),
//! gallery, constraints, transfer, looks; a sixth, positions, when a group has moving
//! lights (docs/touchosc.md).

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

/// Gallery entry buttons on the gallery page (`/vo/pick 1` ... `/vo/pick 12`).
pub const ENTRY_BUTTONS: usize = 12;
/// Saved-look slots on the looks page (save and recall 1 ... 16).
pub const LOOK_SLOTS: usize = 16;
/// Reference-image buttons on the objectives page, at most.
pub const MAX_REFERENCES: usize = 12;
/// Groups on the constraints and transfer pages, at most (the scene's first ones).
pub const MAX_GROUPS: usize = 8;
/// Entries a transfer row offers (`/vo/transfer 1` ... `/vo/transfer 8`).
pub const TRANSFER_ENTRIES: usize = 8;
/// Palette buttons a group's row on the positions page offers, at most (its first ones).
pub const MAX_PALETTES: usize = 8;

/// The layout's size: a 4:3 tablet in landscape.
const WIDTH: i32 = 1024;
const HEIGHT: i32 = 768;
/// Height of the pager's tab bar.
const TABS: i32 = 48;

type Rgba = [f32; 4];
const BACKGROUND: Rgba = [0.08, 0.08, 0.09, 1.0];
const TEXT: Rgba = [0.92, 0.92, 0.92, 1.0];
const ACCENT: Rgba = [1.0, 0.62, 0.2, 1.0];
const ENTRY: Rgba = [0.35, 0.75, 1.0, 1.0];
const NEUTRAL: Rgba = [0.55, 0.55, 0.6, 1.0];
const DANGER: Rgba = [0.95, 0.25, 0.25, 1.0];
const LOOK: Rgba = [0.45, 0.9, 0.5, 1.0];

/// One `<partial>`: a constant or a value of the control, converted and scaled.
#[derive(Debug, Clone, PartialEq)]
pub struct Partial {
    /// `CONSTANT` or `VALUE`.
    pub kind: &'static str,
    /// `INTEGER`, `FLOAT` or `STRING`.
    pub conversion: &'static str,
    /// The constant, or the value's key (`x`, `y`, `text`).
    pub value: String,
    /// Scaling of a value: 0..1 maps to `scale.0`..`scale.1`.
    pub scale: (f32, f32),
}

impl Partial {
    fn constant(conversion: &'static str, value: impl ToString) -> Partial {
        Partial {
            kind: "CONSTANT",
            conversion,
            value: value.to_string(),
            scale: (0.0, 1.0),
        }
    }

    fn constant_str(s: &str) -> Partial {
        Partial::constant("STRING", s)
    }

    fn constant_float(v: f32) -> Partial {
        Partial::constant("FLOAT", v)
    }

    fn constant_int(i: usize) -> Partial {
        Partial::constant("INTEGER", i)
    }

    fn value(key: &str, conversion: &'static str, scale: (f32, f32)) -> Partial {
        Partial {
            kind: "VALUE",
            conversion,
            value: key.to_string(),
            scale,
        }
    }
}

/// One `<osc>` message of a control.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    /// The address (one constant path partial).
    pub path: String,
    /// Sent when the control changes.
    pub send: bool,
    /// Sets the control when the daemon sends this address (feedback).
    pub receive: bool,
    /// Which values trigger a send and on what: (`x`, `RISE`), (`x`, `ANY`),
    /// (`touch`, `ANY`), ...; any one of them sends.
    pub triggers: Vec<(&'static str, &'static str)>,
    /// The arguments.
    pub arguments: Vec<Partial>,
}

impl Message {
    /// A button press: `path args...` on touch-down, nothing on release (docs/osc.md, buttons).
    fn press(path: &str, arguments: Vec<Partial>) -> Message {
        Message {
            path: path.to_string(),
            send: true,
            receive: false,
            triggers: vec![("x", "RISE")],
            arguments,
        }
    }

    /// A continuous control: every change sends the value; the daemon's echo moves it.
    fn value(path: &str, arguments: Vec<Partial>) -> Message {
        Message {
            path: path.to_string(),
            send: true,
            receive: true,
            triggers: vec![("x", "ANY")],
            arguments,
        }
    }

    /// Feedback only: the daemon's push sets the control's value `key`.
    fn listen(path: &str, key: &str, conversion: &'static str) -> Message {
        Message {
            path: path.to_string(),
            send: false,
            receive: true,
            triggers: vec![("x", "ANY")],
            arguments: vec![Partial::value(key, conversion, (0.0, 1.0))],
        }
    }
}

/// A control node.
struct Node {
    kind: &'static str,
    name: String,
    frame: [i32; 4],
    color: Rgba,
    /// Extra properties: (type letter, key, value text).
    props: Vec<(char, &'static str, String)>,
    /// Values: (key, default text).
    values: Vec<(&'static str, String)>,
    messages: Vec<Message>,
    children: Vec<Node>,
}

impl Node {
    fn new(kind: &'static str, name: &str, frame: [i32; 4], color: Rgba) -> Node {
        Node {
            kind,
            name: name.to_string(),
            frame,
            color,
            props: Vec::new(),
            values: vec![("touch", "false".into())],
            messages: Vec::new(),
            children: Vec::new(),
        }
    }

    fn group(name: &str, frame: [i32; 4], children: Vec<Node>) -> Node {
        let mut g = Node::new("GROUP", name, frame, BACKGROUND);
        g.props.push(('b', "interactive", "0".into()));
        g.children = children;
        g
    }
}

/// A label (not touchable, so a button under it still gets the touch).
fn label(name: &str, text: &str, frame: [i32; 4], size: i32) -> Node {
    let mut l = Node::new("LABEL", name, frame, [0.0, 0.0, 0.0, 0.0]);
    l.props.extend([
        ('b', "interactive", "0".into()),
        ('b', "background", "0".into()),
        ('b', "outline", "0".into()),
        ('i', "textSize", size.to_string()),
        ('c', "textColor", color_text(TEXT)),
    ]);
    l.values.push(("text", text.to_string()));
    l
}

/// A label whose text the daemon sets (`path` with one argument).
fn readout(name: &str, path: &str, text: &str, frame: [i32; 4], size: i32) -> Node {
    let mut l = label(name, text, frame, size);
    l.messages.push(Message::listen(path, "text", "STRING"));
    l
}

/// A button with its caption on top: returns the button and the caption label.
fn button(
    name: &str,
    caption: &str,
    frame: [i32; 4],
    color: Rgba,
    messages: Vec<Message>,
) -> [Node; 2] {
    let mut b = Node::new("BUTTON", name, frame, color);
    b.props.push(('i', "buttonType", "0".into()));
    b.values.push(("x", "0".into()));
    b.messages = messages;
    let caption = label(&format!("{name}_caption"), caption, frame, 18);
    [b, caption]
}

fn fader(name: &str, frame: [i32; 4], color: Rgba, default: f32, messages: Vec<Message>) -> Node {
    let mut f = Node::new("FADER", name, frame, color);
    f.values.push(("x", default.to_string()));
    f.messages = messages;
    f
}

/// The objectives page: a button per reference image, aspect buttons and the region pad,
/// all acting on the newest objective (`/vo/objective/last/...`).
fn objectives_page(references: &[String]) -> Node {
    let mut c = vec![label(
        "objectives_title",
        "Reference images (tap to add as an objective)",
        [16, 8, 640, 32],
        18,
    )];
    for (i, image) in references.iter().take(MAX_REFERENCES).enumerate() {
        let (col, row) = ((i % 4) as i32, (i / 4) as i32);
        let stem = image.rsplit_once('.').map_or(image.as_str(), |(s, _)| s);
        c.extend(button(
            &format!("ref_{stem}"),
            stem,
            [16 + col * 156, 48 + row * 84, 144, 72],
            ACCENT,
            vec![Message::press(
                "/vo/objective/add",
                vec![Partial::constant_str(image)],
            )],
        ));
    }
    c.push(label(
        "aspects_title",
        "Newest objective takes",
        [16, 316, 400, 32],
        18,
    ));
    for (i, aspect) in ["intensity", "color", "both"].into_iter().enumerate() {
        c.extend(button(
            &format!("aspects_{aspect}"),
            aspect,
            [16 + i as i32 * 156, 352, 144, 72],
            NEUTRAL,
            vec![Message::press(
                "/vo/objective/last/aspects",
                vec![Partial::constant_str(aspect)],
            )],
        ));
    }
    c.extend(button(
        "objectives_clear",
        "clear all",
        [16, 452, 144, 72],
        DANGER,
        vec![Message::press("/vo/objective/clear", Vec::new())],
    ));
    c.push(label(
        "region_title",
        "Region: drag to aim it and explore",
        [660, 8, 348, 32],
        16,
    ));
    // A half-stage window whose top-left follows the pad: x0 = x/2, x1 = x0 + 1/2. The pad's
    // y grows upwards and image y downwards, hence the reversed scales.
    let mut pad = Node::new("XY", "region", [660, 48, 348, 348], ENTRY);
    pad.values
        .extend([("x", "0.5".into()), ("y", "0.5".into())]);
    pad.messages.push(Message {
        path: "/vo/objective/last/region".into(),
        send: true,
        receive: false,
        triggers: vec![("x", "ANY"), ("y", "ANY")],
        arguments: vec![
            Partial::value("x", "FLOAT", (0.0, 0.5)),
            Partial::value("y", "FLOAT", (0.5, 0.0)),
            Partial::value("x", "FLOAT", (0.5, 1.0)),
            Partial::value("y", "FLOAT", (1.0, 0.5)),
        ],
    });
    // Touching the pad explores: galleries stream while the finger moves (the touch value
    // is 1 from touch-down to release).
    pad.messages.push(Message {
        path: "/vo/explore".into(),
        send: true,
        receive: false,
        triggers: vec![("touch", "ANY")],
        arguments: vec![Partial::value("touch", "INTEGER", (0.0, 1.0))],
    });
    c.push(pad);
    c.extend(button(
        "region_whole",
        "whole stage",
        [660, 412, 348, 72],
        NEUTRAL,
        vec![Message::press("/vo/objective/last/region", Vec::new())],
    ));
    c.push(status_line());
    page("objectives", "Objectives", c)
}

/// The gallery page: generate, the entries (lit while live), stepping, history, fade,
/// master, blackout, progress and what the daemon says.
fn gallery_page() -> Node {
    let mut c = Vec::new();
    c.extend(button(
        "generate",
        "GENERATE",
        [16, 8, 232, 72],
        ACCENT,
        vec![Message::press("/vo/generate", Vec::new())],
    ));
    let mut progress = fader(
        "progress",
        [264, 8, 300, 32],
        ACCENT,
        0.0,
        vec![Message::listen("/vo/progress", "x", "FLOAT")],
    );
    progress.props.extend([
        ('b', "interactive", "0".into()),
        ('i', "orientation", "1".into()),
    ]);
    c.push(progress);
    c.push(label("entries_title", "entries:", [264, 44, 90, 36], 16));
    c.push(readout(
        "entries",
        "/vo/gallery",
        "0",
        [354, 44, 60, 36],
        18,
    ));
    c.extend(button(
        "sync",
        "sync",
        [432, 44, 132, 36],
        NEUTRAL,
        vec![Message::press("/vo/subscribe", Vec::new())],
    ));
    for k in 1..=ENTRY_BUTTONS {
        let i = (k - 1) as i32;
        let (col, row) = (i % 4, i / 4);
        let mut pick = Message::press("/vo/pick", vec![Partial::constant_int(k)]);
        // On release: the push that lights the live entry arrives after it and stays.
        pick.triggers = vec![("x", "FALL")];
        c.extend(button(
            &format!("entry_{k}"),
            &k.to_string(),
            [16 + col * 140, 96 + row * 124, 128, 112],
            ENTRY,
            vec![
                pick,
                Message::listen(&format!("/vo/entry/{k}/lit"), "x", "INTEGER"),
            ],
        ));
    }
    for (i, (name, path)) in [
        ("prev", "/vo/prev"),
        ("next", "/vo/next"),
        ("undo", "/vo/undo"),
        ("redo", "/vo/redo"),
    ]
    .into_iter()
    .enumerate()
    {
        c.extend(button(
            name,
            name,
            [16 + i as i32 * 140, 476, 128, 72],
            NEUTRAL,
            vec![Message::press(path, Vec::new())],
        ));
    }
    c.push(label("fade_title", "fade 0-10 s", [600, 8, 120, 32], 16));
    c.push(fader(
        "fade",
        [600, 44, 120, 504],
        ACCENT,
        0.2,
        vec![Message::value(
            "/vo/fade",
            vec![Partial::value("x", "FLOAT", (0.0, 10.0))],
        )],
    ));
    c.push(label("master_title", "master", [740, 8, 120, 32], 16));
    c.push(fader(
        "master",
        [740, 44, 120, 504],
        TEXT,
        1.0,
        vec![Message::value(
            "/vo/master",
            vec![Partial::value("x", "FLOAT", (0.0, 1.0))],
        )],
    ));
    let [mut blackout, caption] = button(
        "blackout",
        "BLACKOUT",
        [880, 44, 128, 504],
        DANGER,
        vec![Message::value(
            "/vo/blackout",
            vec![Partial::value("x", "INTEGER", (0.0, 1.0))],
        )],
    );
    // A toggle: on and off are both sent; the daemon's push keeps tablets in step.
    blackout.props.retain(|p| p.1 != "buttonType");
    blackout.props.push(('i', "buttonType", "1".into()));
    c.extend([blackout, caption]);
    c.push(status_line());
    page("gallery", "Gallery", c)
}

/// Stage halves and the centre, as pins and transfer regions offer them.
const AREAS: [(&str, [f32; 4]); 5] = [
    ("left half", [0.0, 0.0, 0.5, 1.0]),
    ("right half", [0.5, 0.0, 1.0, 1.0]),
    ("top half", [0.0, 0.0, 1.0, 0.5]),
    ("bottom half", [0.0, 0.5, 1.0, 1.0]),
    ("centre", [0.25, 0.25, 0.75, 0.75]),
];

fn region_partials(r: [f32; 4]) -> Vec<Partial> {
    r.into_iter().map(Partial::constant_float).collect()
}

/// A horizontal fader that sends on every move (the daemon's echo names the group, which a
/// fader cannot match, so it does not listen).
fn slider(name: &str, frame: [i32; 4], default: f32, path: &str, args: Vec<Partial>) -> Node {
    let mut f = fader(
        name,
        frame,
        ACCENT,
        default,
        vec![Message {
            path: path.to_string(),
            send: true,
            receive: false,
            triggers: vec![("x", "ANY")],
            arguments: args,
        }],
    );
    f.props.push(('i', "orientation", "1".into()));
    f
}

/// The constraints page: per group (the scene's first [`MAX_GROUPS`]) its exclusion, its
/// saturation ceiling and its brightness relative to the first group; pins on stage areas.
fn constraints_page(groups: &[String]) -> Node {
    let mut c = vec![
        label("exclude_title", "exclude", [170, 8, 250, 32], 16),
        label("saturation_title", "saturation max", [430, 8, 250, 32], 16),
    ];
    if let Some(first) = groups.first() {
        c.push(label(
            "ratio_title",
            &format!("ratio to {first} (0-2, 0: none)"),
            [700, 8, 308, 32],
            16,
        ));
    }
    for (i, name) in groups.iter().take(MAX_GROUPS).enumerate() {
        let y = 48 + i as i32 * 60;
        c.push(label(&format!("group_{i}"), name, [16, y, 150, 52], 16));
        let g = visobjd_scene::address_segment(name);
        for (j, mode) in ["ignore", "off", "none"].into_iter().enumerate() {
            c.extend(button(
                &format!("exclude_{i}_{mode}"),
                mode,
                [170 + j as i32 * 84, y, 80, 52],
                if mode == "none" { NEUTRAL } else { DANGER },
                vec![Message::press(
                    &format!("/vo/group/{g}/exclude"),
                    vec![Partial::constant_str(mode)],
                )],
            ));
        }
        c.push(slider(
            &format!("saturation_{i}"),
            [430, y, 250, 52],
            1.0,
            &format!("/vo/group/{g}/saturation"),
            vec![
                Partial::constant_float(0.0),
                Partial::value("x", "FLOAT", (0.0, 1.0)),
            ],
        ));
        if i > 0 {
            c.push(slider(
                &format!("ratio_{i}"),
                [700, y, 308, 52],
                0.0,
                &format!("/vo/group/{g}/ratio"),
                vec![
                    Partial::constant_str(&groups[0]),
                    Partial::value("x", "FLOAT", (0.0, 2.0)),
                ],
            ));
        }
    }
    let y = 48 + MAX_GROUPS as i32 * 60;
    c.push(label(
        "pins_title",
        "pin (keep as is)",
        [16, y, 150, 52],
        16,
    ));
    for (j, (name, r)) in AREAS.into_iter().enumerate() {
        c.extend(button(
            &format!("pin_{j}"),
            name,
            [170 + j as i32 * 130, y, 122, 52],
            LOOK,
            vec![Message::press("/vo/pin/add", region_partials(r))],
        ));
    }
    c.push(status_line());
    page("constraints", "Constraints", c)
}

/// The transfer page: a row per group and per stage half, a button per gallery entry:
/// the row's lights take that entry's values (`/vo/transfer k group NAME`, `... region`).
fn transfer_page(groups: &[String]) -> Node {
    let mut c = vec![label(
        "transfer_title",
        "Transfer from entry (onto the stage, with the fade)",
        [16, 8, 992, 32],
        18,
    )];
    let rows = groups
        .iter()
        .take(MAX_GROUPS)
        .map(|g| {
            (
                g.clone(),
                vec![Partial::constant_str("group"), Partial::constant_str(g)],
            )
        })
        .chain(AREAS[..2].iter().map(|(name, r)| {
            let mut args = vec![Partial::constant_str("region")];
            args.extend(region_partials(*r));
            (name.to_string(), args)
        }));
    for (i, (name, args)) in rows.enumerate() {
        let y = 48 + i as i32 * 58;
        c.push(label(
            &format!("transfer_row_{i}"),
            &name,
            [16, y, 150, 50],
            16,
        ));
        for k in 1..=TRANSFER_ENTRIES {
            let mut a = vec![Partial::constant_int(k)];
            a.extend(args.iter().cloned());
            c.extend(button(
                &format!("transfer_{i}_{k}"),
                &k.to_string(),
                [170 + (k as i32 - 1) * 104, y, 96, 50],
                ENTRY,
                vec![Message::press("/vo/transfer", a)],
            ));
        }
    }
    c.push(status_line());
    page("transfer", "Transfer", c)
}

/// A group's row on the positions page: the focus palettes all its moving lights have.
#[derive(Debug, Clone, PartialEq)]
pub struct PaletteRow {
    /// The group's name (its address form is written from it).
    pub group: String,
    /// Each palette's number and label, by number.
    pub palettes: Vec<(u32, Option<String>)>,
}

/// The positions page's rows: every group of `scene` with moving lights that share a
/// palette (all of them, not only the first [`MAX_GROUPS`]: a rig's movers are often a
/// group declared last).
pub fn palette_rows(scene: &visobjd_scene::Scene) -> Vec<PaletteRow> {
    scene
        .groups
        .iter()
        .filter_map(|g| {
            let shared = scene.shared_palettes(&g.lights);
            (!shared.is_empty()).then(|| PaletteRow {
                group: g.name.clone(),
                palettes: shared.iter().map(|p| (p.number, p.name.clone())).collect(),
            })
        })
        .collect()
}

/// The positions page: per group with moving lights (the first [`MAX_GROUPS`]), a button
/// per palette they share (the first [`MAX_PALETTES`]), captioned with its name, that
/// sends its movers there (`/vo/group/<name>/position n`).
fn positions_page(rows: &[PaletteRow]) -> Node {
    let mut c = vec![label(
        "positions_title",
        "Focus palettes (moves the group's moving lights, at once)",
        [16, 8, 992, 32],
        18,
    )];
    for (i, row) in rows.iter().take(MAX_GROUPS).enumerate() {
        let y = 48 + i as i32 * 60;
        c.push(label(
            &format!("positions_group_{i}"),
            &row.group,
            [16, y, 150, 52],
            16,
        ));
        let g = visobjd_scene::address_segment(&row.group);
        for (j, (n, name)) in row.palettes.iter().take(MAX_PALETTES).enumerate() {
            c.extend(button(
                &format!("position_{i}_{n}"),
                name.as_deref().unwrap_or(&n.to_string()),
                [170 + j as i32 * 104, y, 96, 52],
                ENTRY,
                vec![Message::press(
                    &format!("/vo/group/{g}/position"),
                    vec![Partial::constant_int(*n as usize)],
                )],
            ));
        }
    }
    c.push(status_line());
    page("positions", "Positions", c)
}

/// The looks page: save the live look to a slot, recall a slot.
fn looks_page() -> Node {
    let mut c = vec![
        label("save_title", "Save the stage as look", [16, 8, 480, 32], 18),
        label("recall_title", "Recall look", [528, 8, 480, 32], 18),
    ];
    for n in 1..=LOOK_SLOTS {
        let i = (n - 1) as i32;
        let (col, row) = (i % 4, i / 4);
        c.extend(button(
            &format!("save_{n}"),
            &format!("save {n}"),
            [16 + col * 120, 48 + row * 116, 108, 104],
            ACCENT,
            vec![Message::press(
                "/vo/look/save",
                vec![Partial::constant_int(n)],
            )],
        ));
        c.extend(button(
            &format!("recall_{n}"),
            &n.to_string(),
            [528 + col * 120, 48 + row * 116, 108, 104],
            LOOK,
            vec![Message::press(
                "/vo/look/recall",
                vec![Partial::constant_int(n)],
            )],
        ));
    }
    c.push(status_line());
    page("looks", "Looks", c)
}

/// The daemon's one-line status at the foot of a page.
fn status_line() -> Node {
    readout(
        "status",
        "/vo/status/text",
        "tap sync on the gallery page",
        [16, HEIGHT - TABS - 64, WIDTH - 32, 48],
        18,
    )
}

fn page(name: &str, tab: &str, children: Vec<Node>) -> Node {
    let mut g = Node::group(name, [0, TABS, WIDTH, HEIGHT - TABS], children);
    g.props.push(('s', "tabLabel", tab.to_string()));
    g
}

/// The whole layout's XML; `references` are the image names the objectives page offers,
/// `groups` the scene's groups the constraints and transfer pages offer, `palettes` the
/// rows of the positions page (none: no such page).
pub fn layout_xml(references: &[String], groups: &[String], palettes: &[PaletteRow]) -> String {
    let mut pager = Node::new("PAGER", "pages", [0, 0, WIDTH, HEIGHT], BACKGROUND);
    pager.props.extend([
        ('b', "tabbar", "1".into()),
        ('i', "tabbarSize", TABS.to_string()),
    ]);
    pager.values.push(("page", "1".into()));
    pager.children = vec![
        objectives_page(references),
        gallery_page(),
        constraints_page(groups),
        transfer_page(groups),
        looks_page(),
    ];
    if !palettes.is_empty() {
        pager.children.push(positions_page(palettes));
    }
    let root = Node::group("visobjd", [0, 0, WIDTH, HEIGHT], vec![pager]);
    let mut out = String::from("<?xml version='1.0' encoding='UTF-8'?><lexml version='3'>");
    let mut ids = 0u32;
    write_node(&mut out, &root, &mut ids);
    out.push_str("</lexml>");
    out
}

/// The layout, zlib-compressed as TouchOSC reads it.
pub fn layout_tosc(
    references: &[String],
    groups: &[String],
    palettes: &[PaletteRow],
) -> std::io::Result<Vec<u8>> {
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    z.write_all(layout_xml(references, groups, palettes).as_bytes())?;
    z.finish()
}

/// The image files in `dir` (by extension), sorted by name.
pub fn reference_images(dir: &Path) -> std::io::Result<Vec<String>> {
    let mut names: Vec<String> = std::fs::read_dir(dir)?
        .filter_map(Result::ok)
        .filter(|e| e.path().is_file())
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| {
            let lower = n.to_lowercase();
            [".png", ".jpg", ".jpeg"].iter().any(|x| lower.ends_with(x))
        })
        .collect();
    names.sort();
    Ok(names)
}

fn color_text(c: Rgba) -> String {
    format!(
        "<r>{}</r><g>{}</g><b>{}</b><a>{}</a>",
        c[0], c[1], c[2], c[3]
    )
}

/// Text inside CDATA (a `]]>` in it is split across two sections).
fn cdata(s: &str) -> String {
    format!("<![CDATA[{}]]>", s.replace("]]>", "]]]]><![CDATA[>"))
}

fn write_node(out: &mut String, n: &Node, ids: &mut u32) {
    // Stable IDs in UUID form, so regenerating gives the same file.
    *ids += 1;
    let _ = write!(
        out,
        "<node ID='00000000-0000-4000-8000-{:012x}' type='{}'><properties>",
        *ids, n.kind
    );
    let mut props: Vec<(char, &str, String)> = vec![
        ('s', "name", n.name.clone()),
        (
            'r',
            "frame",
            format!(
                "<x>{}</x><y>{}</y><w>{}</w><h>{}</h>",
                n.frame[0], n.frame[1], n.frame[2], n.frame[3]
            ),
        ),
        ('c', "color", color_text(n.color)),
        ('b', "visible", "1".into()),
        ('b', "locked", "0".into()),
    ];
    for p in &n.props {
        props.retain(|q| q.1 != p.1);
        props.push(p.clone());
    }
    props.sort_by(|a, b| a.1.cmp(b.1));
    for (t, key, value) in props {
        let value = match t {
            's' => cdata(&value),
            _ => value,
        };
        let _ = write!(
            out,
            "<property type='{t}'><key>{}</key><value>{value}</value></property>",
            cdata(key)
        );
    }
    out.push_str("</properties><values>");
    for (key, default) in &n.values {
        let _ = write!(
            out,
            "<value><key>{}</key><locked>0</locked><lockedDefaultCurrent>0</lockedDefaultCurrent><default>{}</default><defaultPull>0</defaultPull></value>",
            cdata(key),
            cdata(default)
        );
    }
    out.push_str("</values>");
    if !n.messages.is_empty() {
        out.push_str("<messages>");
        for m in &n.messages {
            let _ = write!(
                out,
                "<osc><enabled>1</enabled><send>{}</send><receive>{}</receive><feedback>0</feedback><connections>00001</connections><triggers>",
                u8::from(m.send),
                u8::from(m.receive),
            );
            for (var, condition) in &m.triggers {
                let _ = write!(
                    out,
                    "<trigger><var>{var}</var><condition>{condition}</condition></trigger>"
                );
            }
            out.push_str("</triggers><path>");
            write_partial(out, &Partial::constant_str(&m.path));
            out.push_str("</path><arguments>");
            for a in &m.arguments {
                write_partial(out, a);
            }
            out.push_str("</arguments></osc>");
        }
        out.push_str("</messages>");
    }
    if !n.children.is_empty() {
        out.push_str("<children>");
        for c in &n.children {
            write_node(out, c, ids);
        }
        out.push_str("</children>");
    }
    out.push_str("</node>");
}

fn write_partial(out: &mut String, p: &Partial) {
    let _ = write!(
        out,
        "<partial><type>{}</type><conversion>{}</conversion><value>{}</value><scaleMin>{}</scaleMin><scaleMax>{}</scaleMax></partial>",
        p.kind,
        p.conversion,
        cdata(&p.value),
        p.scale.0,
        p.scale.1
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regenerating_gives_the_same_layout() {
        let refs = vec!["sunset.png".to_string(), "noir.png".to_string()];
        let groups = vec!["front".to_string(), "back".to_string(), "side".to_string()];
        assert_eq!(
            layout_xml(&refs, &groups, &[]),
            layout_xml(&refs, &groups, &[])
        );
        let xml = layout_xml(&refs, &groups, &[]);
        assert!(!xml.contains("Positions"), "no movers, no positions page");
        assert!(xml.starts_with("<?xml version='1.0' encoding='UTF-8'?><lexml version='3'><node "));
        assert!(xml.contains("<![CDATA[sunset.png]]>"));
        assert_eq!(
            xml.matches("type='BUTTON'").count(),
            2 + 3
                + 2
                + 1
                + 1
                + ENTRY_BUTTONS
                + 4
                + 1
                + 2 * LOOK_SLOTS
                + 3 * 3
                + AREAS.len()
                + (3 + 2) * TRANSFER_ENTRIES
        );
        // A fader per group for saturation, one per group after the first for its ratio.
        assert_eq!(xml.matches("type='FADER'").count(), 3 + 3 + 2);
        assert!(xml.contains("<![CDATA[/vo/group/back/ratio]]>"));
        assert!(
            xml.contains("<var>touch</var>"),
            "the pad explores on touch"
        );
    }

    #[test]
    fn a_group_of_movers_gets_a_button_per_palette_they_share() {
        let row = |group: &str, n: u32| PaletteRow {
            group: group.into(),
            palettes: (1..=n)
                .map(|p| (p, (p != 2).then(|| format!("fp {p}"))))
                .collect(),
        };
        let xml = layout_xml(&[], &[], &[row("spots L", 3), row("wide", 12)]);
        assert!(xml.contains("<![CDATA[Positions]]>"));
        let sends = |path: &str| xml.matches(&format!("<![CDATA[{path}]]>")).count();
        assert_eq!(sends("/vo/group/spots_L/position"), 3);
        assert_eq!(sends("/vo/group/wide/position"), MAX_PALETTES);
        // Captioned with the palette's name, or its number without one.
        assert!(xml.contains("<![CDATA[fp 3]]>") && xml.contains("<![CDATA[2]]>"));
        assert!(xml.contains("<![CDATA[position_1_8]]>"));
        assert!(!xml.contains("<![CDATA[position_1_9]]>"));
    }

    #[test]
    fn cdata_survives_its_terminator() {
        assert_eq!(cdata("a]]>b"), "<![CDATA[a]]]]><![CDATA[>b]]>");
    }
}
