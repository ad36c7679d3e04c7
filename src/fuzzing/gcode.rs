//! The G-code front end on arbitrary bytes: the interpreter (scanner, expressions, O-word flow,
//! modal state) must never panic, and whatever it yields must be usable downstream: finite
//! points, continuous elements, valid arcs, and a plan that the planner accepts.

use crate::gcode::{Interpreter, Item, Setup, Tool, ToolTable};
use crate::planner::{AuxLimits, Limits, PlannerConfig, plan_items_with};
use nalgebra::Vector3;

/// The interpreter and the planner on `data` as a program.
pub fn program(data: &[u8]) {
    let mut setup = Setup::new(Vector3::new(1.0, -2.0, 3.0));
    let mut tools = ToolTable::new();
    tools.insert(
        1,
        Tool {
            radius_mm: 2.0,
            length_mm: 50.0,
        },
    );
    setup.tools = tools;
    // Every auxiliary axis, A wrapped, so that their words are read too.
    setup.aux_axes = [true; 6];
    setup.aux_wrapped = [true, false, false, false, false, false];
    setup.start_aux = [10.0, -20.0, 0.0, 1.0, 0.0, -1.0];
    let mut position = setup.start_mm;
    let mut aux = setup.start_aux;
    let mut items = Vec::new();
    // A program may loop forever with motion: read a bounded number of items.
    for item in Interpreter::new(data, "fuzz.ngc", setup).take(5000) {
        match item {
            Ok(Item::Motion(e)) => {
                assert_eq!(e.start_mm, position, "elements must chain");
                assert_eq!(e.aux.start, aux, "the auxiliary axes must chain");
                assert!(e.aux.end.iter().all(|c| c.is_finite()));
                aux = e.aux.end;
                assert!(e.end_mm.iter().all(|c| c.is_finite()));
                assert_eq!(e.rapid, e.feed_mm_s.is_none());
                if let Some(f) = e.feed_mm_s {
                    assert!(f.is_finite() && f > 0.0);
                }
                if e.arc().is_none() {
                    assert!(matches!(e.kind, crate::gcode::ElementKind::Line));
                }
                let (lo, hi) = e.bounds_mm();
                assert!(lo.iter().chain(hi.iter()).all(|c| !c.is_nan()));
                position = e.end_mm;
                items.push(Item::Motion(e));
            }
            Ok(item) => items.push(item),
            Err(e) => {
                let _ = e.to_string();
                break;
            }
        }
    }
    let limits = Limits {
        max_vel_mm_s: Vector3::new(500.0, 500.0, 200.0),
        max_acc_mm_s2: Vector3::new(5000.0, 5000.0, 2000.0),
        max_feed_mm_s: 500.0,
    };
    let config = PlannerConfig {
        aux: AuxLimits {
            max_vel: [360.0, 360.0, 360.0, 100.0, 100.0, 100.0],
            max_acc: [3600.0, 3600.0, 3600.0, 1000.0, 1000.0, 1000.0],
            max_jerk: [1.0e5; 6],
        },
        ..PlannerConfig::exact_stop()
    };
    if let Ok(plan) = plan_items_with(Vector3::new(1.0, -2.0, 3.0), &items, &limits, &config) {
        let _ = plan.position_at(plan.duration_s() * 0.5);
    }
}
