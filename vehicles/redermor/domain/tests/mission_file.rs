//! The mission file: the examples load, and every kind of error names its field.

mod common;

use redermor::mission::{DepthTarget, EndArea, Mission, Problem};

/// A valid mission, in pieces so that each test can spoil one.
fn text(area: &str, forbidden: &str, start: &str, end: &str, vehicle: &str) -> String {
    format!(
        "name = \"t\"\nstart = {start}\n[vehicle]\n{vehicle}\n{area}\n{forbidden}\n[end]\n{end}\n"
    )
}

const AREA: &str =
    "[[area]]\nname = \"a\"\npolygon = [[0.0, 100.0], [100.0, 100.0], [100.0, 200.0], [0.0, 200.0]]\ndepth = 10.0";
const ZONE: &str =
    "[[forbidden]]\nname = \"z\"\npolygon = [[200.0, 0.0], [300.0, 0.0], [300.0, 50.0], [200.0, 50.0]]";
const START: &str = "[0.0, 0.0]";
const END: &str = "point = [500.0, 500.0]";

/// The error for `field`, with its message; fails when there is none.
fn error_for(text: &str, field: &str) -> (Problem, String) {
    let errors = Mission::from_toml(text).expect_err("the mission should be refused");
    let e = errors
        .for_field(field)
        .unwrap_or_else(|| panic!("no error for {field}, got:\n{errors}"));
    let message = e.to_string();
    assert!(
        message.starts_with(&format!("{field}: ")),
        "the message names the field: {message}"
    );
    assert!(errors.to_string().contains(&message));
    (e.problem.clone(), message)
}

#[test]
fn the_examples_and_the_readme_load() {
    for m in common::missions() {
        assert!(!m.areas.is_empty() && !m.forbidden.is_empty());
    }
    let two = common::mission(common::TWO_AREAS);
    assert_eq!(two.area("bravo").unwrap().depth, DepthTarget::Altitude(8.0));
    assert!(two.area("bravo").unwrap().predicted_current.is_some());
    assert!(matches!(two.end, EndArea::Polygon(_)));
    assert!((two.seabed.depth_at(geo::coord! {x: 100.0, y: 0.0}) - 41.0).abs() < 1e-9);
    let island = common::mission(common::ISLAND_PASSAGE);
    assert!(matches!(island.end, EndArea::Point { radius, .. } if radius == 25.0));

    let readme = include_str!("../README.md");
    let start = readme.find("```toml\n").expect("a toml example") + "```toml\n".len();
    let block = &readme[start..start + readme[start..].find("```").unwrap()];
    let m = Mission::from_toml(block).unwrap_or_else(|e| panic!("README example:\n{e}"));
    assert_eq!(m.areas.len(), 2);
    assert_eq!(m.vehicle.line_spacing(), 48.0);
}

#[test]
fn a_valid_mission_passes() {
    let m = Mission::from_toml(&text(AREA, ZONE, START, END, "")).unwrap();
    assert_eq!(m.areas[0].name, "a");
    assert_eq!(m.forbidden[0].name, "z");
    // Defaults apply to what the file leaves out.
    assert_eq!(m.vehicle.cruise_speed, 1.5);
    assert_eq!(m.seabed.depth, 50.0);
    assert!(matches!(m.end, EndArea::Point { radius, .. } if radius == m.vehicle.arrival_radius));
}

#[test]
fn polygon_errors_name_the_polygon() {
    let two_points = "[[area]]\nname = \"a\"\npolygon = [[0.0, 100.0], [100.0, 100.0], [0.0, 100.0]]\ndepth = 10.0";
    let (p, m) = error_for(&text(two_points, ZONE, START, END, ""), "area[0].polygon");
    assert_eq!(p, Problem::TooFewPoints { points: 2 });
    assert!(m.contains("at least 3"), "{m}");

    let bowtie = "[[forbidden]]\nname = \"z\"\npolygon = [[200.0, 0.0], [300.0, 50.0], [300.0, 0.0], [200.0, 50.0]]";
    let (p, m) = error_for(&text(AREA, bowtie, START, END, ""), "forbidden[0].polygon");
    assert_eq!(p, Problem::SelfIntersecting);
    assert!(m.contains("crosses itself"), "{m}");

    let flat = "[[area]]\nname = \"a\"\npolygon = [[0.0, 100.0], [50.0, 100.0], [100.0, 100.0]]\ndepth = 10.0";
    let (p, _) = error_for(&text(flat, ZONE, START, END, ""), "area[0].polygon");
    assert_eq!(p, Problem::Degenerate);

    let nan = "[[area]]\nname = \"a\"\npolygon = [[0.0, nan], [100.0, 100.0], [100.0, 200.0]]\ndepth = 10.0";
    let (p, _) = error_for(&text(nan, ZONE, START, END, ""), "area[0].polygon");
    assert_eq!(p, Problem::NotFinite);

    let (p, _) = error_for(
        &text(AREA, ZONE, START, "polygon = [[1.0, 1.0], [2.0, 2.0]]", ""),
        "end.polygon",
    );
    assert_eq!(p, Problem::TooFewPoints { points: 2 });
}

#[test]
fn geometry_conflicts_name_both_sides() {
    let over = "[[forbidden]]\nname = \"wreck\"\npolygon = [[50.0, 150.0], [300.0, 150.0], [300.0, 300.0], [50.0, 300.0]]";
    let (p, m) = error_for(&text(AREA, over, START, END, ""), "area[0].polygon");
    assert!(matches!(p, Problem::OverlapsForbidden { ref zone, .. } if zone == "wreck"));
    assert!(m.contains("\"wreck\" (forbidden[0])"), "{m}");

    let (p, m) = error_for(&text(AREA, ZONE, "[250.0, 25.0]", END, ""), "start");
    assert_eq!(p, Problem::StartInForbidden { zone: "z".into() });
    assert!(m.contains("inside the forbidden zone \"z\""), "{m}");

    let (p, _) = error_for(
        &text(
            AREA,
            ZONE,
            START,
            "point = [250.0, 60.0]\nradius = 20.0",
            "",
        ),
        "end.point",
    );
    assert!(matches!(p, Problem::OverlapsForbidden { .. }));
}

#[test]
fn names_must_be_unique_and_present() {
    let twice = format!("{AREA}\n{}", AREA.replace("0.0, 100.0]", "0.0, 101.0]"));
    let (p, m) = error_for(&text(&twice, ZONE, START, END, ""), "area[1].name");
    assert_eq!(
        p,
        Problem::DuplicateName {
            name: "a".into(),
            first: "area[0].name".into()
        }
    );
    assert!(m.contains("already used by area[0].name"), "{m}");
    // Across areas and zones too.
    let zone_a = ZONE.replace("name = \"z\"", "name = \"a\"");
    let (p, _) = error_for(&text(AREA, &zone_a, START, END, ""), "area[0].name");
    assert!(matches!(p, Problem::DuplicateName { .. }));
    let empty = AREA.replace("name = \"a\"", "name = \" \"");
    let (p, _) = error_for(&text(&empty, ZONE, START, END, ""), "area[0].name");
    assert_eq!(p, Problem::EmptyName);
}

#[test]
fn choices_and_ranges_name_their_field() {
    let both = AREA.replace("depth = 10.0", "depth = 10.0\naltitude = 5.0");
    let (p, m) = error_for(&text(&both, ZONE, START, END, ""), "area[0].depth");
    assert_eq!(
        p,
        Problem::OneOf {
            fields: ["depth", "altitude"],
            given: 2
        }
    );
    assert!(m.contains("exactly one of `depth` and `altitude`"), "{m}");
    let neither = AREA.replace("depth = 10.0", "");
    error_for(&text(&neither, ZONE, START, END, ""), "area[0].depth");
    error_for(
        &text(
            AREA,
            ZONE,
            START,
            "point = [1.0, 1.0]\npolygon = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]",
            "",
        ),
        "end",
    );

    let (p, m) = error_for(
        &text(AREA, ZONE, START, END, "line_overlap = 1.5"),
        "vehicle.line_overlap",
    );
    assert!(matches!(p, Problem::OutOfRange { value, .. } if value == 1.5));
    assert!(m.contains("from 0 to 0.9"), "{m}");
    error_for(
        &text(AREA, ZONE, START, END, "cruise_speed = 0.0"),
        "vehicle.cruise_speed",
    );
    error_for(
        &text(AREA, ZONE, START, END, "swath_width = inf"),
        "vehicle.swath_width",
    );
    let deep = AREA.replace("depth = 10.0", "depth = -1.0");
    error_for(&text(&deep, ZONE, START, END, ""), "area[0].depth");
    let fast = format!("{AREA}\ncurrent = [5.0, 0.0]");
    error_for(&text(&fast, ZONE, START, END, ""), "area[0].current");
    error_for(&text(AREA, ZONE, "[nan, 0.0]", END, ""), "start");
    error_for(
        &text(
            AREA,
            ZONE,
            START,
            "point = [500.0, 500.0]\nradius = 0.0",
            "",
        ),
        "end.radius",
    );
    let (p, _) = error_for(&text("", ZONE, START, END, ""), "area");
    assert_eq!(p, Problem::NoArea);
}

#[test]
fn syntax_errors_name_the_field_when_toml_does() {
    let (p, m) = error_for("name = \"t\"\n[end]\npoint = [0.0, 0.0]\n", "start");
    assert!(matches!(p, Problem::Syntax(_)));
    assert!(m.contains("missing field `start`"), "{m}");
    let (_, m) = error_for(&text(AREA, ZONE, START, END, "speed = 2.0"), "speed");
    assert!(m.contains("unknown field `speed`"), "{m}");
    let errors = Mission::from_toml("name = ").unwrap_err();
    assert_eq!(errors.0.len(), 1);
}

#[test]
fn every_problem_is_reported_at_once() {
    let bad_area = "[[area]]\nname = \"a\"\npolygon = [[0.0, 0.0], [1.0, 1.0]]\ndepth = 10.0";
    let errors = Mission::from_toml(&text(
        bad_area,
        ZONE,
        "[250.0, 25.0]",
        END,
        "line_overlap = 2.0",
    ))
    .unwrap_err();
    let fields: Vec<&str> = errors.0.iter().map(|e| e.field.as_str()).collect();
    for f in ["vehicle.line_overlap", "area[0].polygon", "start"] {
        assert!(fields.contains(&f), "{f} missing from {fields:?}");
    }
}
