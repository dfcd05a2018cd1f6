//! PLN: paths keep clear of the forbidden zones, the itinerary visits every area once then the
//! end, surveys cover their areas along the current, and the replans.

mod common;

use common::*;
use redermor::geom::{self, pos, Position};
use redermor::mission::{representative_point, Current, DepthTarget, Mission};
use redermor::plan::{LegKind, PlanError, Planner, StageKind, Trajectory};

/// Every leg of `t` keeps the safety margin from every forbidden zone (1 mm of rounding
/// allowed), measured with geo.
fn assert_clear(mission: &Mission, t: &Trajectory, what: &str) {
    for (i, leg) in t.legs.iter().enumerate() {
        let c = clearance(mission, leg.from, leg.to);
        assert!(
            c >= mission.vehicle.safety_margin - 1e-3,
            "{what}: leg {i} {:?} -> {:?} passes {c:.2} m from a forbidden zone",
            leg.from,
            leg.to
        );
    }
}

/// Legs are continuous: each starts where the previous ends.
fn assert_continuous(t: &Trajectory, what: &str) {
    for w in t.legs.windows(2) {
        assert!(
            geom::distance(w[0].to, w[1].from) < 1e-9,
            "{what}: gap between legs"
        );
    }
}

#[test]
fn mission_plans_keep_clear_of_forbidden_zones_and_visit_every_area_once_then_the_end() {
    for mission in missions() {
        let planner = Planner::new(&mission);
        let plan = planner.plan_mission().unwrap();
        let all = plan.trajectory();
        assert_clear(&mission, &all, &mission.name);
        assert_continuous(&all, &mission.name);
        assert_eq!(all.legs.first().unwrap().from, mission.start);
        assert!(
            mission.end.contains(all.end().unwrap()),
            "ends in the end area"
        );

        // Stages: (transit to A, survey A) for each area of the itinerary, then the end.
        let mut order = plan.itinerary.order.clone();
        order.sort_unstable();
        assert_eq!(
            order,
            (0..mission.areas.len()).collect::<Vec<_>>(),
            "each area once"
        );
        let expected: Vec<StageKind> = plan
            .itinerary
            .order
            .iter()
            .flat_map(|&i| {
                let name = mission.areas[i].name.clone();
                [
                    StageKind::TransitToArea(name.clone()),
                    StageKind::Survey(name),
                ]
            })
            .chain([StageKind::TransitToEnd])
            .collect();
        let kinds: Vec<StageKind> = plan.stages.iter().map(|s| s.kind.clone()).collect();
        assert_eq!(kinds, expected);
        // Transit legs are at transit depth, survey legs at the area's.
        for stage in &plan.stages {
            for leg in &stage.trajectory.legs {
                match (&stage.kind, &leg.kind) {
                    (StageKind::Survey(a), LegKind::SurveyLine { area, .. })
                    | (StageKind::Survey(a), LegKind::LineChange { area }) => {
                        assert_eq!(a, area);
                        assert_eq!(leg.depth, mission.area(a).unwrap().depth);
                    }
                    (StageKind::Survey(_), other) => panic!("survey leg of kind {other:?}"),
                    (_, LegKind::Transit) => {
                        assert_eq!(leg.depth, DepthTarget::Depth(mission.vehicle.transit_depth))
                    }
                    (_, other) => panic!("transit leg of kind {other:?}"),
                }
            }
        }
        // Course changes: one per waypoint where the heading changes, the turn in (-π, π].
        for c in all.course_changes() {
            assert!(c.turn().abs() <= std::f64::consts::PI && c.turn() != 0.0);
            assert_eq!(all.legs[c.leg].from, c.at);
        }
    }
}

#[test]
fn the_itinerary_goes_round_the_wreck_field() {
    let mission = mission(TWO_AREAS);
    let planner = Planner::new(&mission);
    let alpha = representative_point(&mission.area("alpha").unwrap().polygon);
    assert!(
        clearance(&mission, mission.start, alpha) == 0.0,
        "the straight line from the start to alpha crosses the wreck field"
    );
    let path = planner.path(mission.start, alpha).unwrap();
    assert!(path.len() > 2, "a detour: {path:?}");
    for w in path.windows(2) {
        assert!(clearance(&mission, w[0], w[1]) >= mission.vehicle.safety_margin - 1e-3);
    }
    // The detour is not absurd: shorter than going round the zone's far side twice.
    let straight = geom::distance(mission.start, alpha);
    let length: f64 = path.windows(2).map(|w| geom::distance(w[0], w[1])).sum();
    assert!(
        length > straight && length < 2.0 * straight,
        "{length} vs {straight}"
    );
}

#[test]
fn lawnmower_lines_cover_the_area_and_lie_along_the_current() {
    for mission in missions() {
        let planner = Planner::new(&mission);
        for area in &mission.areas {
            for current in [
                None,
                Some(Current::new(0.3, 0.1)),
                Some(Current::new(0.0, -0.4)),
            ] {
                let survey = planner.survey(&area.name, mission.start, current).unwrap();
                let lines: Vec<(Position, Position)> = survey
                    .trajectory
                    .legs
                    .iter()
                    .filter(|l| matches!(l.kind, LegKind::SurveyLine { .. }))
                    .map(|l| (l.from, l.to))
                    .collect();
                assert!(!lines.is_empty());
                let half_swath = mission.vehicle.swath_width / 2.0;
                for p in grid_inside(&area.polygon, 5.0) {
                    let nearest = lines
                        .iter()
                        .map(|&(a, b)| to_segment(p, a, b))
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        nearest <= half_swath,
                        "{}: {p:?} is {nearest:.1} m from every line (current {current:?})",
                        area.name
                    );
                }
                if let Some(c) = current {
                    for &(a, b) in &lines {
                        // Parallel: the cross product of the line and the current is nil.
                        let d = b - a;
                        let cross = (d.x * c.north - d.y * c.east) / (d.x.hypot(d.y) * c.speed());
                        assert!(cross.abs() < 1e-6, "line {a:?}->{b:?} not along {c:?}");
                    }
                }
                // Neighbouring lines are one spacing apart (the swath less the overlap).
                assert!((survey.spacing - mission.vehicle.line_spacing()).abs() < 1e-12);
                assert_clear(&mission, &survey.trajectory, &area.name);
                assert_continuous(&survey.trajectory, &area.name);
            }
        }
    }
}

#[test]
fn the_survey_starts_at_the_corner_nearest_the_arrival() {
    let mission = mission(TWO_AREAS);
    let planner = Planner::new(&mission);
    let area = mission.area("alpha").unwrap();
    for corner in area.polygon.exterior().0.iter().take(4) {
        let arrival = *corner + (*corner - pos(100.0, 675.0)) * 0.5;
        let survey = planner.survey("alpha", arrival, None).unwrap();
        let entry = survey.entry().unwrap();
        // The four ways in: either end of the first row or of the last.
        let (first, last) = (survey.lines[0], *survey.lines.last().unwrap());
        let best = [first.0, first.1, last.0, last.1]
            .into_iter()
            .map(|e| geom::distance(arrival, e))
            .fold(f64::INFINITY, f64::min);
        assert_eq!(entry, first.0);
        assert!((geom::distance(arrival, entry) - best).abs() < 1e-9);
        assert!(
            geom::distance(entry, *corner) < 60.0,
            "entry {entry:?} near {corner:?}"
        );
    }
}

#[test]
fn replans_to_the_end_area_for_a_current_and_for_an_inspection() {
    let mission = mission(TWO_AREAS);
    let planner = Planner::new(&mission);

    // Alarm: from north of the wreck field, straight to the end area round it.
    let from = pos(75.0, 480.0);
    let home = planner.to_end_area(from).unwrap();
    assert_eq!(home.legs[0].from, from);
    assert!(mission.end.contains(home.end().unwrap()));
    assert!(home.legs.len() > 1, "must go round the wreck field");
    assert_clear(&mission, &home, "to end");
    assert_continuous(&home, "to end");

    // New operative sequence for bravo in a current from another direction.
    let c = Current::new(-0.2, 0.35);
    let s = planner.survey("bravo", pos(480.0, 590.0), Some(c)).unwrap();
    let heading = s.line_heading;
    assert!((heading - c.set_towards() % std::f64::consts::PI).abs() < 1e-12);
    let predicted = planner
        .survey(
            "bravo",
            pos(480.0, 590.0),
            mission.area("bravo").unwrap().predicted_current,
        )
        .unwrap();
    assert!(
        (predicted.line_heading - heading).abs() > 0.1,
        "a different pattern"
    );

    // Inspection around Q from where the survey stopped, then back there.
    let stop = pos(600.0, 400.0);
    let q = pos(650.0, 450.0);
    let t = planner
        .inspection(stop, q, 20.0, DepthTarget::Altitude(8.0))
        .unwrap();
    assert_eq!(t.legs.first().unwrap().from, stop);
    assert_eq!(t.end(), Some(stop));
    assert_continuous(&t, "inspection");
    let square: Vec<Position> = t
        .legs
        .iter()
        .filter(|l| l.kind == LegKind::Inspection)
        .map(|l| l.to)
        .collect();
    for corner in [(-20.0, -20.0), (-20.0, 20.0), (20.0, 20.0), (20.0, -20.0)] {
        let c = q + pos(corner.0, corner.1);
        assert!(
            square.iter().any(|&p| geom::distance(p, c) < 1e-9),
            "corner {c:?}"
        );
    }
    assert!(t.legs.iter().any(|l| l.kind == LegKind::Return));
    // An inspection near the wreck field goes round it too.
    let near = planner
        .inspection(
            pos(75.0, 480.0),
            pos(75.0, 200.0),
            15.0,
            DepthTarget::Depth(10.0),
        )
        .unwrap();
    assert_clear(&mission, &near, "inspection beyond the wreck field");

    // The survey resumes where it stopped.
    let survey = planner.survey("bravo", pos(480.0, 590.0), None).unwrap();
    let rest = survey.trajectory.remainder_from(2, stop);
    assert_eq!(rest.legs.len(), survey.trajectory.legs.len() - 2);
    assert_eq!(rest.legs[0].from, stop);
    assert_eq!(rest.legs[0].to, survey.trajectory.legs[2].to);
}

#[test]
fn planning_errors_are_reported_not_panicked() {
    let mission = mission(TWO_AREAS);
    let planner = Planner::new(&mission);
    let inside = pos(0.0, 300.0);
    match planner.to_end_area(inside) {
        Err(PlanError::InForbidden { zone, .. }) => assert_eq!(zone, "wreck_field"),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        planner.survey("charlie", mission.start, None).unwrap_err(),
        PlanError::UnknownArea("charlie".into())
    );
    assert!(planner
        .inspection(
            mission.start,
            pos(0.0, 300.0),
            10.0,
            DepthTarget::Depth(5.0)
        )
        .is_err());
    assert!(matches!(
        planner.inspection(
            mission.start,
            pos(10.0, 10.0),
            -1.0,
            DepthTarget::Depth(5.0)
        ),
        Err(PlanError::BadArgument(_))
    ));

    // A point walled in by four zones whose margins meet: no path.
    let walled = Mission::from_toml(
        r#"
        name = "walled"
        start = [0.0, 0.0]
        [vehicle]
        safety_margin = 20.0
        [[area]]
        name = "a"
        polygon = [[-50.0, -50.0], [-10.0, -50.0], [-10.0, -10.0], [-50.0, -10.0]]
        depth = 5.0
        [[forbidden]]
        name = "south"
        polygon = [[400.0, 400.0], [600.0, 400.0], [600.0, 420.0], [400.0, 420.0]]
        [[forbidden]]
        name = "north"
        polygon = [[400.0, 580.0], [600.0, 580.0], [600.0, 600.0], [400.0, 600.0]]
        [[forbidden]]
        name = "west"
        polygon = [[400.0, 445.0], [420.0, 445.0], [420.0, 555.0], [400.0, 555.0]]
        [[forbidden]]
        name = "east"
        polygon = [[580.0, 445.0], [600.0, 445.0], [600.0, 555.0], [580.0, 555.0]]
        [end]
        point = [500.0, 500.0]
        "#,
    )
    .unwrap();
    let planner = Planner::new(&walled);
    assert!(matches!(
        planner.plan_mission(),
        Err(PlanError::NoPath { .. })
    ));
    let e = planner.to_end_area(pos(0.0, 0.0)).unwrap_err();
    assert!(e.to_string().contains("no path"), "{e}");
}

#[test]
fn the_itinerary_is_the_shortest_order() {
    // Areas along a line east of the start, listed out of order: the itinerary takes them in
    // order of distance, exactly (4 areas) and by nearest neighbour (9 areas).
    for count in [4usize, 9] {
        let mut text = String::from("name = \"line\"\nstart = [0.0, 0.0]\n");
        let mut ranks: Vec<usize> = (0..count).collect();
        ranks.reverse();
        ranks.swap(0, count / 2);
        for &k in &ranks {
            let x = 200.0 + 200.0 * k as f64;
            text += &format!(
                "[[area]]\nname = \"a{k}\"\npolygon = [[{x}, -20.0], [{}, -20.0], [{}, 20.0], [{x}, 20.0]]\ndepth = 5.0\n",
                x + 40.0,
                x + 40.0
            );
        }
        text += &format!(
            "[end]\npoint = [{}, 0.0]\n",
            200.0 * (count as f64 + 1.0) + 100.0
        );
        let m = Mission::from_toml(&text).unwrap();
        let it = Planner::new(&m).itinerary(m.start).unwrap();
        let names: Vec<&str> = it.order.iter().map(|&i| m.areas[i].name.as_str()).collect();
        let expected: Vec<String> = (0..count).map(|k| format!("a{k}")).collect();
        assert_eq!(names, expected, "{count} areas");
        assert!(it.length > 200.0 * count as f64);
    }
}
