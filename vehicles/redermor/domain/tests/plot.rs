//! The plots: SVG files written where asked, well-formed XML, with Figure 9's colours, the
//! traces and the events.

mod common;

use common::*;
use plotters::style::RGBColor;
use redermor::geom::pos;
use redermor::plot::{
    self, Trace, TraceEvent, TracePoint, FORBIDDEN, PLANNED, SURVEY_AREA, VEHICLE,
};
use redermor::sensors::Scenario;
use redermor::sim::{MissionRun, RunConfig};

/// Parses `svg` to the end; returns the element names seen.
fn elements(svg: &str) -> Vec<String> {
    let mut reader = quick_xml::Reader::from_str(svg);
    let mut names = Vec::new();
    loop {
        match reader.read_event() {
            Ok(quick_xml::events::Event::Eof) => break,
            Ok(quick_xml::events::Event::Start(e)) | Ok(quick_xml::events::Event::Empty(e)) => {
                names.push(String::from_utf8_lossy(e.name().as_ref()).into_owned())
            }
            Ok(_) => {}
            Err(e) => panic!("not well-formed XML at {}: {e}", reader.buffer_position()),
        }
    }
    names
}

fn hex(c: RGBColor) -> String {
    format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
}

#[test]
fn a_run_gives_a_figure_9_map_and_a_depth_plot() {
    let mission = mission(TWO_AREAS);
    let scenario = Scenario::from_toml("[[fault]]\nat = 900.0\nkind = \"leak\"\n").unwrap();
    let report = MissionRun::new(&mission, &scenario, RunConfig::default())
        .unwrap()
        .run();
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("map.svg");
    let depth = dir.path().join("depth.svg");
    plot::write_map(&map, &mission, &report.trace).unwrap();
    plot::write_depth(&depth, &report.trace).unwrap();

    let svg = std::fs::read_to_string(&map).unwrap();
    let names = elements(&svg);
    assert_eq!(names.first().map(String::as_str), Some("svg"));
    assert!(names.iter().any(|n| n == "polygon"), "filled areas");
    assert!(names.iter().any(|n| n == "polyline"), "traces");
    assert!(names.iter().any(|n| n == "text"), "labels");
    for (what, colour) in [
        ("survey areas", SURVEY_AREA),
        ("forbidden zones", FORBIDDEN),
        ("planned trace", PLANNED),
        ("vehicle trace", VEHICLE),
    ] {
        assert!(svg.contains(&hex(colour)), "no {what} ({})", hex(colour));
    }
    // Blue is blue, red red, yellow yellow, green green.
    assert_eq!(hex(SURVEY_AREA), "#0000FF");
    assert_eq!(hex(FORBIDDEN), "#FF0000");
    assert_eq!(hex(PLANNED), "#FFFF00");
    assert_eq!(hex(VEHICLE), "#00A000");
    assert!(
        svg.contains("alarm (Leak)"),
        "the alarm is marked where it happened"
    );
    assert!(svg.contains("end area reached"));
    // The planned and replanned traces: one yellow polyline each.
    let yellow = svg.matches(&format!("stroke=\"{}\"", hex(PLANNED))).count();
    assert_eq!(yellow, report.trace.planned.len(), "{yellow} yellow lines");

    let svg = std::fs::read_to_string(&depth).unwrap();
    let names = elements(&svg);
    assert!(names.iter().any(|n| n == "polyline"));
    assert!(svg.contains(&hex(VEHICLE)));
    assert!(svg.contains("depth (m)") && svg.contains("time (s)"));
    assert!(svg.contains("alarm (Leak)"));
    drop(dir);
}

#[test]
fn small_and_odd_traces_still_plot() {
    let mission = mission(ISLAND_PASSAGE);
    for trace in [
        Trace::default(),
        Trace {
            points: vec![TracePoint {
                time: 0.0,
                position: pos(0.0, 0.0),
                depth: 0.0,
                surveying: None,
            }],
            events: vec![
                TraceEvent {
                    time: f64::NAN,
                    position: pos(f64::NAN, 1.0),
                    label: "nowhere".into(),
                },
                TraceEvent {
                    time: 0.0,
                    position: pos(10.0, 10.0),
                    label: "odd <event> & co".into(),
                },
            ],
            planned: vec![vec![]],
        },
    ] {
        for size in [(400, 300), (0, 0), (5, 3)] {
            if let Ok(svg) = plot::map_svg(&mission, &trace, size) {
                elements(&svg);
            }
            if let Ok(svg) = plot::depth_svg(&trace, size) {
                elements(&svg);
            }
        }
        let svg = plot::map_svg(&mission, &trace, (400, 300)).unwrap();
        // Labels are escaped (the XML parsed), and an event with no position is not drawn.
        assert_eq!(
            svg.contains("odd &lt;event&gt; &amp; co"),
            !trace.events.is_empty()
        );
        assert!(!svg.contains("nowhere"));
    }
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no/such/dir/map.svg");
    let e = plot::write_map(&missing, &mission, &Trace::default()).unwrap_err();
    assert!(e.to_string().contains("cannot write"), "{e}");
}
