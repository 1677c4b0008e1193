use sim_bridge::agent::*;
use sim_bridge::expert::Expert;
use sim_bridge::map::Map;
use sim_bridge::route::{plan::*, planner::plan_route, sets::RouteSet, xml};
use sim_bridge::world::*;
fn main() {
    let id = std::env::args().nth(1).unwrap();
    let set = RouteSet::find("town05-long-style").unwrap();
    let map = Map::from_str(
        "t",
        sim_bridge::towngen::bundled(set.town),
        Default::default(),
    )
    .unwrap();
    let specs = xml::parse("x", set.bundled_xml()).unwrap();
    let spec = specs.iter().find(|s| s.id == id).unwrap();
    let dense = plan_route(&map, spec).unwrap();
    let plan = global_plan(&dense);
    let mut f = RouteFollower::new(plan.clone());
    let mut ex = Expert::new();
    ex.start_route(&RouteContext {
        map: &map,
        route: &dense,
        plan: &plan,
    });
    let seed: u64 = std::env::args()
        .nth(2)
        .map(|s| s.parse().unwrap())
        .unwrap_or(0);
    let mut w = World::new(
        &map,
        &dense,
        WorldConfig {
            seed,
            ..WorldConfig::default()
        },
    );
    let mut still = 0;
    let mut prog = 0;
    for frame in 0..20000u64 {
        let e = w.ego_state();
        prog = dense.advance_index(prog, e.position.truncate(), 5);
        w.trigger_scenarios(prog);
        let n = f.step(e.position.truncate());
        let obs = Observation {
            time: w.time,
            frame,
            speed: e.speed,
            position: e.position,
            yaw: e.yaw,
            compass: 0.0,
            command: n.option,
            target_point: to_ego_frame(n.position, e.position, e.yaw).truncate(),
            frames: vec![],
        };
        let c = ex.run_step(&obs, &w);
        if e.speed < 0.1 {
            still += 1
        } else {
            still = 0
        }
        if still == 400 {
            println!(
                "t={:.1} stuck at {:?} prog {} lane {:?} ctrl {:?}",
                w.time, e.position, prog, dense.points[prog].lane, c
            );
            println!("  {:?}", ex.debug_view(&w));
            for a in w.actors() {
                let d = (a.obb.centre - e.position.truncate()).length();
                if d < 25.0 {
                    println!(
                        "  actor {} {:?} d {:.1} at {:?} v {:?}",
                        a.id, a.kind, d, a.obb.centre, a.velocity
                    );
                }
            }
            let p = e.position.truncate();
            for l in &map.lights {
                if (l.trigger_centre() - p).length() < 40.0 {
                    println!(
                        "  light {} {:?} at {:?}",
                        l.id,
                        w.light_states()[l.id],
                        l.trigger_centre()
                    );
                }
            }
            for sgn in &map.stop_signs {
                for l in &sgn.stop_lines {
                    if (l.position.truncate() - p).length() < 30.0 {
                        println!(
                            "  sign {} line lane {:?} at {:?}",
                            sgn.id, l.lane, l.position
                        );
                    }
                }
            }
            for k in prog..(prog + 12).min(dense.points.len()) {
                let q = dense.points[k];
                println!(
                    "  route {} lane {:?} junc {:?} opt {:?} {:?}",
                    k,
                    q.lane,
                    map.lane(q.lane).junction,
                    q.option,
                    q.position.truncate()
                );
            }
            break;
        }
        let hits = w.step(c);
        if let Some(h) = hits.first() {
            println!(
                "t={:.2} HIT id {} ego {:?} yaw {:.2} v {:.2} ctrl {:?} view {:?}",
                w.time,
                h.other_id,
                e.position,
                e.yaw,
                e.speed,
                c,
                ex.debug_view(&w)
            );
            for v in &w.traffic.vehicles {
                if v.id == h.other_id {
                    println!(
                        "  other lane {:?} junc {:?} s {:.1} speed {:.2} lat {:.2} next {:?} pose {:?} runner {}",
                        v.lane,
                        map.lane(v.lane).junction,
                        v.s,
                        v.speed,
                        v.lateral,
                        v.next,
                        v.pose(&map),
                        v.ignores_lights
                    );
                }
            }
            println!(
                "  ego lane {:?}",
                map.lane_for_pose(e.position, e.yaw)
                    .map(|(l, p)| (l, map.lane(l).junction, p.s))
            );
            break;
        }
    }
}
