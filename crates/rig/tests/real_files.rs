//! The parsers on real files written by others (tests/fixtures/rig/README.md says where
//! each comes from). Every expected value was read from the file by hand, and the comment
//! says where it is; `tests/cli/import.rs` also checks the MVR and the GDTF against
//! Python's own zipfile and xml.etree reading.

use std::path::PathBuf;

use visobjd_rig::gdtf::GdtfType;
use visobjd_rig::ofl::OflType;
use visobjd_scene::profile::Slot;

fn read(name: &str) -> (String, Vec<u8>) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/rig")
        .join(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (name.to_string(), bytes)
}

#[test]
fn gdtf_led_par_rgbw_becomes_a_profile_with_its_emitters() {
    let (name, bytes) = read("BlenderDMX@LED_PAR_64_RGBW@v0.3.gdtf");
    let ty = GdtfType::parse(&name, &bytes).expect("parses");
    // <FixtureType ... Manufacturer="BlenderDMX" Name="LED PAR 64 RGBW">, one
    // <DMXMode Name="Default"> with Offset="1" to Offset="5".
    assert_eq!(ty.manufacturer, "BlenderDMX");
    assert_eq!(ty.modes.len(), 1);
    assert_eq!(ty.modes[0].footprint(), 5);
    let ft = ty.fixture_type("Default").expect("mode");
    assert_eq!(ft.name, "BlenderDMX LED PAR 64 RGBW (Default)");
    let p = ft.profile.expect("a profile");
    // Attributes Dimmer, ColorAdd_R, ColorAdd_G, ColorAdd_B, ColorAdd_W in offset order.
    assert_eq!(
        p.slots,
        [
            Slot::Intensity,
            Slot::Red,
            Slot::Green,
            Slot::Blue,
            Slot::White
        ]
    );
    // <Emitter Color="0.640100,0.330000,21.260000" ... Name="Red">, and so on; the
    // channel functions do not link them (no Emitter=), so they are matched by name.
    let want = [
        ("red", [0.6401, 0.33], 21.26),
        ("green", [0.3, 0.6], 71.52),
        ("blue", [0.15, 0.06001], 7.22),
        ("white", [0.3127, 0.329], 100.0),
    ];
    for (e, (n, xy, flux)) in p.emitters.iter().zip(want) {
        assert_eq!((e.name.as_str(), e.xy, e.flux), (n, xy, flux));
    }
    // XYZ of red at full: X = x / y * Y.
    let red = p.emitters_xyz()[0];
    assert!((red[0] - 0.6401 / 0.33 * 21.26).abs() < 1e-9, "{red:?}");
}

#[test]
fn gdtf_robe_ispiiderx_reads_16_bit_channels_links_and_refuses_cells() {
    let (name, bytes) = read("Robe@Robin_iSpiiderX@python-gdtf-test1.gdtf");
    let ty = GdtfType::parse(&name, &bytes).expect("parses");
    assert_eq!(
        (ty.manufacturer.as_str(), ty.name.as_str()),
        ("Robe Lighting", "Robin iSpiiderX")
    );
    assert_eq!(ty.modes.len(), 10);
    // <Emitter Color="0.702028,0.297316,19.150713" DominantWaveLength="626.419983" Name="Red">
    assert_eq!(ty.emitters[0].name, "Red");
    assert_eq!(ty.emitters[0].color, Some([0.702028, 0.297316, 19.150713]));
    let pattern = ty
        .modes
        .iter()
        .find(|m| m.name == "Mode 6 - Pattern")
        .expect("mode 6");
    // Its last DMXChannel is Head_Dimmer with Offset="46,47"; Background_Dimmer is
    // Offset="18,19" with Default="65535/2"; Background_Shutter1 (Offset="17") has
    // <ChannelSet DMXFrom="32/1" Name="Open"/>; Background_ColorAdd_R links Emitter="Red".
    assert_eq!(pattern.footprint(), 47);
    let dimmer = pattern
        .channels
        .iter()
        .find(|c| c.offsets == [18, 19])
        .expect("18,19");
    assert_eq!(
        (dimmer.attribute.as_str(), dimmer.default),
        ("Dimmer", 65535)
    );
    let shutter = pattern
        .channels
        .iter()
        .find(|c| c.offsets == [17])
        .expect("17");
    assert_eq!(
        (shutter.attribute.as_str(), shutter.open),
        ("Shutter1", Some(32))
    );
    let red = pattern
        .channels
        .iter()
        .find(|c| c.offsets == [8, 9])
        .expect("8,9");
    assert_eq!(red.emitter.as_deref(), Some("Red"));
    // <DMXChannel ... Geometry="Yoke" ... Offset="1,2"> > <ChannelFunction Attribute="Pan"
    // ... PhysicalFrom="-270.000000" PhysicalTo="270.000000">, and the Head's Tilt at
    // Offset="3,4" with PhysicalFrom="110.000000" PhysicalTo="-110.000000" (reversed).
    let pan = pattern
        .channels
        .iter()
        .find(|c| c.offsets == [1, 2])
        .expect("1,2");
    assert_eq!(
        (pan.attribute.as_str(), pan.physical),
        ("Pan", Some((-270.0, 270.0)))
    );
    let tilt = pattern
        .channels
        .iter()
        .find(|c| c.offsets == [3, 4])
        .expect("3,4");
    assert_eq!(
        (tilt.attribute.as_str(), tilt.physical),
        ("Tilt", Some((110.0, -110.0)))
    );
    assert_eq!(
        dimmer.physical, None,
        "only Pan and Tilt keep their physical range"
    );
    // Three virtual Dimmer channels (Offset="") in Mode 10 are not slots.
    let mode10 = &ty.modes[0];
    assert_eq!(mode10.name, "Mode 10 - Pattern full RGBW");
    assert!(mode10.channels.iter().all(|c| !c.offsets.is_empty()));
    // Every mode has several Dimmers (zones) or two DMX breaks: listed, never guessed.
    for ft in ty.fixture_types() {
        let why = ft.profile.expect_err("multi-cell");
        assert!(
            why.contains("multi-cell") || why.contains("DMX breaks"),
            "{why}"
        );
    }
    let e = ty
        .fixture_type("Mode 11")
        .expect_err("no such mode")
        .to_string();
    assert!(e.starts_with(&format!("{name}: Robe Lighting Robin iSpiiderX: has no DMX mode `Mode 11` (modes: `Mode 10 - Pattern full RGBW`")), "{e}");
}

#[test]
fn ofl_modes_become_profiles_with_16_bit_dimmers_and_seven_emitters() {
    let (name, bytes) = read("cameo-root-par-6.json");
    let ty = OflType::parse(&name, &bytes).expect("parses");
    // modes[6] "11-channel": Dimmer, Dimmer fine ("fineChannelAliases": ["Dimmer fine"]),
    // Strobe Multifunctional (Open at dmxRange [0, 5]), Red, Green, Blue, White, Amber,
    // UV, Color Preset, Sound Control (no defaultValue: 0).
    let ft = ty.fixture_type("11-channel").expect("mode");
    assert_eq!(ft.footprint, Some(11));
    let p = ft.profile.expect("a profile");
    assert_eq!(p.footprint(), 11);
    assert_eq!(
        p.channel_names(),
        [
            "intensity16",
            "fixed:0",
            "red",
            "green",
            "blue",
            "white",
            "amber",
            "uv",
            "fixed:0",
            "fixed:0"
        ]
    );
    // The short name works too ("shortName": "4ch2": Red, Green, Blue, White).
    let rgbw = ty
        .fixture_type("4ch2")
        .expect("short name")
        .profile
        .expect("profile");
    assert_eq!(
        rgbw.slots,
        [Slot::Red, Slot::Green, Slot::Blue, Slot::White]
    );
    assert!(!rgbw.has_intensity());

    let (name, bytes) = read("etc-source-four-led-series-2-lustr.json");
    let ty = OflType::parse(&name, &bytes).expect("parses");
    // "Direct": Red, Lime, Amber, Green, Cyan, Blue, Indigo, Intensity, Strobe, Fan Control.
    let p = ty
        .fixture_type("Direct")
        .expect("mode")
        .profile
        .expect("profile");
    assert_eq!(
        p.channel_names(),
        [
            "red",
            "lime",
            "amber",
            "green",
            "emitter:cyan",
            "blue",
            "emitter:indigo",
            "intensity",
            "fixed:0",
            "fixed:0"
        ]
    );
    assert_eq!(p.emitters.len(), 7);
    assert_eq!(p.emitters_xyz().len(), 7);
    // "RGB Plus 7" has both "Red Emulated" and "Red" (each ColorIntensity Red).
    let why = ty
        .fixture_type("RGB Plus 7")
        .expect("mode")
        .profile
        .expect_err("two reds");
    assert!(why.contains("emitter `red` is used by two slots"), "{why}");

    let (name, bytes) = read("etc-colorsource-par-deep-blue.json");
    let ty = OflType::parse(&name, &bytes).expect("parses");
    // "Direct": Intensity, Red, Green, Indigo, Lime, Strobe.
    let p = ty
        .fixture_type("Direct")
        .expect("mode")
        .profile
        .expect("profile");
    assert_eq!(
        p.slots,
        [
            Slot::Intensity,
            Slot::Red,
            Slot::Green,
            Slot::Emitter(2),
            Slot::Lime,
            Slot::Fixed(0)
        ]
    );
    assert_eq!(p.emitters[2].name, "indigo");
}

#[test]
fn mvr_capture_show_reads_every_fixture_and_lists_the_stub_types() {
    let (name, bytes) = read("capture_demo_show.mvr");
    let rig = visobjd_rig::mvr::parse(&name, &bytes).expect("parses");
    // 76 <Fixture> nodes; the first: name="Alpha Spot QWO 800", <FixtureID>11</FixtureID>,
    // <Address break="0">513</Address> = universe 2 address 1, in layer "Truss Lights"
    // outside any GroupObject; the next is FixtureID 12 at 545 = universe 2 address 33.
    assert_eq!(rig.fixtures.len(), 76);
    let f = &rig.fixtures[0];
    assert_eq!(
        (f.channel, f.universe, f.address, f.group.as_deref()),
        (11, 2, 1, None)
    );
    assert_eq!(f.name, "Alpha Spot QWO 800");
    assert_eq!(
        (
            rig.fixtures[1].channel,
            rig.fixtures[1].universe,
            rig.fixtures[1].address
        ),
        (12, 2, 33)
    );
    // FixtureID 1 (A.leda Wash K20) sits in a GroupObject without a name, the first such
    // group holding fixtures.
    let one = rig
        .fixtures
        .iter()
        .find(|f| f.channel == 1)
        .expect("channel 1");
    assert_eq!(
        (one.universe, one.address, one.group.as_deref()),
        (1, 1, Some("group 1"))
    );
    // Capture wrote stub fixture types: DMX channels with attributes Dimmer1..DimmerN, no
    // Dimmer and no colour. Each is listed with its footprint and channels, not guessed.
    let needs = rig.needs_profiles();
    assert_eq!(needs.len(), 5);
    assert!(needs.contains(&"needs a profile: Clay Paky Alpha Spot QWO 800 (Standard [Lamp Dmx] [Color Mixing=Cmy]) (32 channels), channels 11-20: no Dimmer and no colour channel, so visobjd cannot make it give light".to_string()), "{needs:?}");
}

#[test]
fn mvr_basic_fixture_without_an_id_is_not_a_light() {
    let (name, bytes) = read("basic_fixture.mvr");
    let rig = visobjd_rig::mvr::parse(&name, &bytes).expect("parses");
    // <FixtureID>0</FixtureID>, no FixtureIDNumeric, and every Address is 0.
    assert!(rig.fixtures.is_empty());
    assert_eq!(
        rig.skipped,
        ["fixture \"LED PAR 64 RGBW\": no numeric FixtureID (`0`), so no channel"]
    );
}

#[test]
fn a_library_finds_types_by_the_names_a_console_patch_uses() {
    let mut library = visobjd_rig::Library::default();
    let (name, bytes) = read("BlenderDMX@LED_PAR_64_RGBW@v0.3.gdtf");
    library.add_gdtf(&name, &bytes).expect("gdtf");
    let (name, bytes) = read("etc-source-four-led-series-2-lustr.json");
    library.add_ofl(&name, &bytes).expect("ofl");
    let par = library.find("blenderdmx led par 64 rgbw", "Default");
    assert_eq!(par.expect("known").expect("mode").footprint, Some(5));
    // LongName="LED PAR 64 RGBW" works as well.
    assert!(library.find("LED PAR 64 RGBW", "Default").is_some());
    let lustr = library.find("Source Four LED Series 2 Lustr", "Direct");
    assert_eq!(lustr.expect("known").expect("mode").footprint, Some(10));
    let e = library.find("Source Four LED Series 2 Lustr", "Nope");
    assert!(e.expect("known type").is_err());
    assert!(library.find("Acme Wash 7", "Default").is_none());
    let (name, bytes) = read("cameo-root-par-6.json");
    assert!(
        library.add_gdtf(&name, &bytes).is_err(),
        "JSON is not a GDTF"
    );
}

#[test]
fn a_library_finds_types_by_their_eos_names() {
    let mut library = visobjd_rig::Library::default();
    for f in [
        "BlenderDMX@LED_PAR_64_RGBW@v0.3.gdtf",
        "etc-source-four-led-series-2-lustr.json",
        "etc-colorsource-par-deep-blue.json",
        "cameo-root-par-6.json",
    ] {
        let (name, bytes) = read(f);
        if f.ends_with(".gdtf") {
            library.add_gdtf(&name, &bytes).expect("gdtf");
        } else {
            library.add_ofl(&name, &bytes).expect("ofl");
        }
    }
    fn find(library: &visobjd_rig::Library, maker: &str, model: &str) -> Result<String, String> {
        match library.find_eos(maker, model) {
            Some(Ok(t)) => Ok(t.name),
            Some(Err(e)) => Err(e),
            None => Err("none".to_string()),
        }
    }
    let found = |maker: &str, model: &str| find(&library, maker, model);
    // One mode ("Default"): the name alone will do, or with the mode.
    assert_eq!(
        found("BlenderDMX", "LED_PAR_64_RGBW"),
        Ok("BlenderDMX LED PAR 64 RGBW (Default)".into())
    );
    assert_eq!(
        found("blenderdmx", "LED_PAR_64_RGBW_Default"),
        Ok("BlenderDMX LED PAR 64 RGBW (Default)".into())
    );
    // OFL: the manufacturer is the start of the file's name; modes by name or shortName
    // ("HSI Plus 7" / "HSI+7").
    assert_eq!(
        found("ETC", "Source_Four_LED_Series_2_Lustr_HSI_Plus_7"),
        Ok("Source Four LED Series 2 Lustr (HSI Plus 7)".into())
    );
    assert_eq!(
        found("ETC", "Source_Four_LED_Series_2_Lustr_HSI+7"),
        Ok("Source Four LED Series 2 Lustr (HSI Plus 7)".into())
    );
    assert_eq!(
        found("Cameo", "ROOT_PAR_6_8-channel"),
        Ok("ROOT PAR 6 (8-channel)".into())
    );
    // Several modes and no mode named: not guessed.
    assert!(found("Cameo", "ROOT_PAR_6").is_err_and(|e| e == "none"));
    // Another manufacturer's file does not match.
    assert!(found("Chauvet", "ROOT_PAR_6_8-channel").is_err_and(|e| e == "none"));
    assert!(found("ETC", "ColorSource_PAR_Deep_Blue_Nope").is_err_and(|e| e == "none"));
    // The same type in two files: listed, not picked.
    let (_, bytes) = read("cameo-root-par-6.json");
    library
        .add_ofl("cameo/root-par-6.json", &bytes)
        .expect("ofl");
    let e = find(&library, "Cameo", "ROOT_PAR_6_8-channel").expect_err("two files match");
    assert!(e.starts_with("several fixture types match it"), "{e}");
}

#[test]
fn ofl_moving_head_pans_and_tilts_through_its_angles() {
    let (name, bytes) = read("stairville-mh-100.json");
    let ty = OflType::parse(&name, &bytes).expect("parses");
    // "Pan": {"fineChannelAliases": ["Pan fine"], "capability": {"type": "Pan",
    // "angleStart": "0deg", "angleEnd": "630deg"}}; "Tilt" likewise to "220deg".
    // modes[1] "14-Channel": Pan, Pan fine, Tilt, Tilt fine, Pan/Tilt Speed, Dimmer, Red,
    // Green, Blue, White, Color Temperature, Constant Color, Strobe, Special Functions
    // (no defaultValue anywhere: held at 0).
    let p = ty
        .fixture_type("14-Channel")
        .expect("mode")
        .profile
        .expect("a profile");
    assert_eq!(p.footprint(), 14);
    assert_eq!(
        p.channel_names(),
        [
            "pan16",
            "tilt16",
            "fixed:0",
            "intensity",
            "red",
            "green",
            "blue",
            "white",
            "fixed:0",
            "fixed:0",
            "fixed:0",
            "fixed:0"
        ]
    );
    assert!(p.is_moving());
    assert_eq!((p.pan_range, p.tilt_range), (630.0, 220.0));
    // modes[0] "9-Channel" (shortName "9ch"): Pan, Tilt without their fine bytes.
    let p = ty
        .fixture_type("9ch")
        .expect("mode")
        .profile
        .expect("a profile");
    assert_eq!(&p.slots[..2], [Slot::Pan, Slot::Tilt]);
    assert_eq!((p.pan_range, p.tilt_range), (630.0, 220.0));
    // The travel goes into scene.toml's [[profile]] as pan_range and tilt_range.
    let file = p.to_file();
    assert_eq!(
        (file.pan_range, file.tilt_range),
        (Some(630.0), Some(220.0))
    );
}
