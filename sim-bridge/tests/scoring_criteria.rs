//! The leaderboard 1.0 criteria, each provoked on purpose on tiny hand-written OpenDRIVE maps by
//! a scripted "agent" (a sequence of poses at 20 Hz), with the exact coefficient checked.

/// Named `scoring` so that `cargo test -p sim-bridge scoring` selects these tests.
mod scoring {

    use glam::{DVec2, DVec3};
    use sim_bridge::map::{LaneIdx, LaneKind, Map, MapOptions};
    use sim_bridge::route::{DenseRoute, RoutePoint};
    use sim_bridge::scoring::{
        InfractionKind, RouteEnd, RouteRecord, RouteScorer, Rules, ScoringConfig, route_timeout,
    };
    use sim_bridge::world::state::{CollisionClass, CollisionEvent, EgoState, LightState};
    use ssrdrive_proto::camera::{CameraSpec, Rig};
    use ssrdrive_proto::command::RoadOption;

    const DT: f64 = 0.05;

    /// A straight 200 m road along +x: two driving lanes each way (3.5 m), a parking lane (2.5 m)
    /// on the right (south) side and a sidewalk on the left (north) side. Right-hand traffic: lanes
    /// -1 (y = -1.75) and -2 (y = -5.25) run along +x, the parking lane -3 is centred on y = -8.25
    /// and the road's south edge is at y = -9.5.
    const STRAIGHT: &str = r#"<?xml version="1.0" standalone="yes"?>
    <OpenDRIVE>
      <header revMajor="1" revMinor="4" name="straight" version="1.0"/>
      <road name="main" length="200" id="1" junction="-1">
        <link/>
        <planView>
          <geometry s="0" x="0" y="0" hdg="0" length="200"><line/></geometry>
        </planView>
        <lanes>
          <laneSection s="0">
            <left>
              <lane id="3" type="sidewalk" level="false"><link/><width sOffset="0" a="2.0" b="0" c="0" d="0"/></lane>
              <lane id="2" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
              <lane id="1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
            </left>
            <center><lane id="0" type="none" level="false"/></center>
            <right>
              <lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
              <lane id="-2" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>
              <lane id="-3" type="parking" level="false"><link/><width sOffset="0" a="2.5" b="0" c="0" d="0"/></lane>
            </right>
          </laneSection>
        </lanes>
      </road>
    </OpenDRIVE>
    "#;

    /// Two roads joined by a junction: road 1 (x 0..100), connector road 3 (x 100..120, in junction
    /// 1), road 2 (x 120..220), one driving lane each way. `SIGNAL` is placed on road 1 at s = 95,
    /// facing the +s traffic (lane -1, whose stop line is at x = 100).
    const JUNCTION: &str = r#"<?xml version="1.0" standalone="yes"?>
    <OpenDRIVE>
      <header revMajor="1" revMinor="4" name="junction" version="1.0"/>
      <road name="in" length="100" id="1" junction="-1">
        <link><successor elementType="junction" elementId="1"/></link>
        <planView><geometry s="0" x="0" y="0" hdg="0" length="100"><line/></geometry></planView>
        <lanes>
          <laneSection s="0">
            <left><lane id="1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></left>
            <center><lane id="0" type="none" level="false"/></center>
            <right><lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>
          </laneSection>
        </lanes>
        <signals>SIGNAL</signals>
      </road>
      <road name="out" length="100" id="2" junction="-1">
        <link><predecessor elementType="junction" elementId="1"/></link>
        <planView><geometry s="0" x="120" y="0" hdg="0" length="100"><line/></geometry></planView>
        <lanes>
          <laneSection s="0">
            <left><lane id="1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></left>
            <center><lane id="0" type="none" level="false"/></center>
            <right><lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>
          </laneSection>
        </lanes>
      </road>
      <road name="connector" length="20" id="3" junction="1">
        <link>
          <predecessor elementType="road" elementId="1" contactPoint="end"/>
          <successor elementType="road" elementId="2" contactPoint="start"/>
        </link>
        <planView><geometry s="0" x="100" y="0" hdg="0" length="20"><line/></geometry></planView>
        <lanes>
          <laneSection s="0">
            <left><lane id="1" type="driving" level="false"><link><predecessor id="1"/><successor id="1"/></link><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></left>
            <center><lane id="0" type="none" level="false"/></center>
            <right><lane id="-1" type="driving" level="false"><link><predecessor id="-1"/><successor id="-1"/></link><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>
          </laneSection>
        </lanes>
      </road>
      <junction id="1" name="j1">
        <connection id="0" incomingRoad="1" connectingRoad="3" contactPoint="start">
          <laneLink from="-1" to="-1"/>
        </connection>
        <connection id="1" incomingRoad="2" connectingRoad="3" contactPoint="end">
          <laneLink from="1" to="1"/>
        </connection>
      </junction>
    </OpenDRIVE>
    "#;

    const TRAFFIC_LIGHT: &str = r#"<signal s="95" t="-4" id="10" name="light" dynamic="yes" orientation="+" zOffset="3" country="OpenDRIVE" type="1000001" subtype="-1" value="-1" height="1" width="0.5"/>"#;
    const STOP_SIGN: &str = r#"<signal s="95" t="-4" id="20" name="stop" dynamic="no" orientation="+" zOffset="2" country="DE" type="206" subtype="-1" value="-1" height="1" width="1"/>"#;

    fn straight_map() -> Map {
        Map::from_str("straight", STRAIGHT, MapOptions::default()).expect("straight map loads")
    }

    fn junction_map(signal: &str) -> Map {
        let xml = JUNCTION.replace("SIGNAL", signal);
        Map::from_str("junction", &xml, MapOptions::default()).expect("junction map loads")
    }

    /// The driving lane with this road id and lane id (first section).
    fn lane(map: &Map, road: &str, id: i32) -> LaneIdx {
        map.lanes
            .iter()
            .find(|l| l.kind == LaneKind::Driving && l.road_id == road && l.lane_id == id)
            .unwrap_or_else(|| panic!("no driving lane {road}/{id}"))
            .idx
    }

    /// A dense route sampled every 1 m along `lanes` (consecutive lanes chained end to start).
    fn dense_route(map: &Map, lanes: &[LaneIdx]) -> DenseRoute {
        let mut points = Vec::new();
        for (i, &idx) in lanes.iter().enumerate() {
            let l = map.lane(idx);
            let steps = l.length().round() as usize;
            let first = if i == 0 { 0 } else { 1 };
            for k in first..=steps {
                let s = l.length() * k as f64 / steps as f64;
                let pose = l.pose_at(s);
                points.push(RoutePoint {
                    position: pose.position,
                    yaw: pose.yaw,
                    option: RoadOption::LaneFollow,
                    lane: idx,
                });
            }
        }
        let keypoint_length =
            (points.last().unwrap().position - points.first().unwrap().position).length();
        DenseRoute::new(points, keypoint_length)
    }

    fn ego_at(x: f64, y: f64, speed: f64) -> EgoState {
        EgoState {
            position: DVec3::new(x, y, 0.0),
            yaw: 0.0,
            speed,
            half_extent: DVec2::new(2.45, 1.06),
        }
    }

    /// A scripted run: feeds poses to a scorer tick by tick.
    struct Drive<'a> {
        scorer: RouteScorer<'a>,
        t: f64,
        end: Option<RouteEnd>,
        /// The background vehicles' mean speed every tick.
        traffic_speed: Option<f64>,
    }

    impl<'a> Drive<'a> {
        fn new(map: &'a Map, route: &'a DenseRoute) -> Self {
            Self::with(map, route, ScoringConfig::default())
        }

        fn with(map: &'a Map, route: &'a DenseRoute, config: ScoringConfig) -> Self {
            Self {
                scorer: RouteScorer::new(map, route, config),
                t: 0.0,
                end: None,
                traffic_speed: None,
            }
        }

        /// One tick at `ego`; returns the end, if any.
        fn step(
            &mut self,
            ego: EgoState,
            collisions: &[CollisionEvent],
            lights: &[LightState],
        ) -> Option<RouteEnd> {
            assert!(self.end.is_none(), "ticked after the route ended");
            self.end = self
                .scorer
                .tick(self.t, &ego, collisions, lights, self.traffic_speed);
            self.t += DT;
            self.end
        }

        /// Drive along y at `speed` from x0 until x1 (exclusive) or the route ends; `lateral` gives
        /// the y for each x, `lights` the light states for each x.
        fn cruise(
            &mut self,
            x0: f64,
            x1: f64,
            speed: f64,
            lateral: impl Fn(f64) -> f64,
            lights: impl Fn(f64) -> Vec<LightState>,
        ) -> Option<RouteEnd> {
            let mut x = x0;
            while x < x1 && self.end.is_none() {
                self.step(ego_at(x, lateral(x), speed), &[], &lights(x));
                x += speed * DT;
            }
            self.end
        }

        fn count(&self, kind: InfractionKind) -> usize {
            self.scorer
                .infractions()
                .iter()
                .filter(|i| i.kind == kind)
                .count()
        }

        fn finish(self) -> RouteRecord {
            let t = self.t;
            self.scorer.finish(self.end, "RouteScenario_0", 0, t, 1.0)
        }
    }

    fn no_lights(_: f64) -> Vec<LightState> {
        Vec::new()
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    // ---------------------------------------------------------------------------------------------
    // Maps and routes

    #[test]
    fn test_maps_have_the_expected_lanes_and_controls() {
        let map = straight_map();
        let driving = map
            .lanes
            .iter()
            .filter(|l| l.kind == LaneKind::Driving)
            .count();
        let parking = map
            .lanes
            .iter()
            .filter(|l| l.kind == LaneKind::Parking)
            .count();
        assert_eq!((driving, parking), (4, 1));
        let l = map.lane(lane(&map, "1", -1));
        assert!(
            close(l.pose_at(10.0).position.y, -1.75, 1e-3),
            "{:?}",
            l.pose_at(10.0)
        );
        assert!(close(l.length(), 200.0, 1e-3));

        let map = junction_map(TRAFFIC_LIGHT);
        assert_eq!(map.junctions.len(), 1);
        let light = light_of(&map);
        assert_eq!(light.stop_lines.len(), 1);
        assert!(close(light.stop_lines[0].position.x, 100.0, 1e-3));
        assert!(map.stop_signs.is_empty());

        let map = junction_map(STOP_SIGN);
        assert_eq!(map.stop_signs.len(), 1);
        assert!(close(
            map.stop_signs[0].stop_lines[0].position.x,
            100.0,
            1e-3
        ));
    }

    fn light_of(map: &Map) -> &sim_bridge::map::TrafficLight {
        let incoming = lane(map, "1", -1);
        map.lights
            .iter()
            .find(|l| l.stop_lines.iter().any(|s| s.lane == incoming))
            .expect("a light controls road 1 lane -1")
    }

    fn junction_route(map: &Map) -> DenseRoute {
        dense_route(
            map,
            &[lane(map, "1", -1), lane(map, "3", -1), lane(map, "2", -1)],
        )
    }

    fn straight_route(map: &Map) -> DenseRoute {
        dense_route(map, &[lane(map, "1", -1)])
    }

    // ---------------------------------------------------------------------------------------------
    // Route completion

    #[test]
    fn clean_drive_completes_with_full_scores() {
        let map = straight_map();
        let route = straight_route(&map);
        assert_eq!(route.points.len(), 201);
        let mut d = Drive::new(&map, &route);
        assert_eq!(
            d.cruise(0.0, 260.0, 8.0, |_| -1.75, no_lights),
            Some(RouteEnd::Completed)
        );
        let r = d.finish();
        assert_eq!(r.status, "Completed");
        assert_eq!(r.scores.score_route, 100.0);
        assert_eq!(r.scores.score_penalty, 1.0);
        assert_eq!(r.scores.score_composed, 100.0);
        assert!(r.infractions.outside_route_lanes.is_empty());
        assert!(close(r.meta.route_length, 200.0, 1e-6));
    }

    #[test]
    fn bench2drive_figures_of_a_clean_drive_behind_faster_traffic() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        d.traffic_speed = Some(10.0);
        d.cruise(0.0, 260.0, 8.0, |_| -1.75, no_lights);
        let figures = d.finish().meta.bench2drive.expect("figures");
        assert!(figures.success);
        // Every checkpoint: 8 m/s against the traffic's 10.
        assert!(
            close(figures.efficiency.unwrap(), 80.0, 1e-9),
            "{figures:?}"
        );
        assert_eq!(figures.comfort, Some(100.0));
        // Without background traffic every checkpoint is 100 %.
        let mut alone = Drive::new(&map, &route);
        alone.cruise(0.0, 260.0, 8.0, |_| -1.75, no_lights);
        let figures = alone.finish().meta.bench2drive.expect("figures");
        assert_eq!(figures.efficiency, Some(100.0));
    }

    #[test]
    fn leaderboard_2_rules_call_a_clean_drive_perfect_and_penalise_a_slow_one() {
        let map = straight_map();
        let route = straight_route(&map);
        let lb2 = || ScoringConfig {
            rules: Rules::Lb2,
            ..ScoringConfig::default()
        };
        let mut clean = Drive::with(&map, &route, lb2());
        clean.traffic_speed = Some(8.0);
        clean.cruise(0.0, 260.0, 8.0, |_| -1.75, no_lights);
        let r = clean.finish();
        assert_eq!(r.status, "Perfect");
        assert!(r.completed());
        assert_eq!(r.scores.score_composed, 100.0);
        assert!(r.infractions.min_speed_infractions.is_empty());

        // Half the traffic's speed: each of the 4 checkpoints (3 on the way, 1 at the end)
        // multiplies IS by 1 - 0.3 * (1 - 0.5).
        let mut slow = Drive::with(&map, &route, lb2());
        slow.traffic_speed = Some(8.0);
        slow.cruise(0.0, 260.0, 4.0, |_| -1.75, no_lights);
        assert_eq!(slow.count(InfractionKind::MinSpeed), 3);
        let r = slow.finish();
        assert_eq!(r.status, "Completed");
        assert_eq!(r.infractions.min_speed_infractions.len(), 4);
        assert_eq!(
            r.infractions.min_speed_infractions[0],
            "Average speed is 50.0% of the surrounding traffic's one"
        );
        assert!(close(r.scores.score_penalty, 0.85f64.powi(4), 1e-12));
        assert!(
            r.meta.bench2drive.unwrap().success,
            "Bench2Drive excuses minimum speed"
        );

        // The same slow drive under 1.0's rules: no such penalty.
        let mut lb1 = Drive::new(&map, &route);
        lb1.traffic_speed = Some(8.0);
        lb1.cruise(0.0, 260.0, 4.0, |_| -1.75, no_lights);
        let r = lb1.finish();
        assert_eq!(
            (r.status.as_str(), r.scores.score_penalty),
            ("Completed", 1.0)
        );
    }

    #[test]
    fn a_scenario_timeout_costs_0_7_and_is_listed_under_leaderboard_2_rules() {
        let map = straight_map();
        let route = straight_route(&map);
        let lb2 = ScoringConfig {
            rules: Rules::Lb2,
            ..ScoringConfig::default()
        };
        assert_eq!(lb2.rules.scenario_timeout(), Some(240.0));
        assert_eq!(Rules::Lb1.scenario_timeout(), None, "1.0 has no such rule");
        let mut d = Drive::with(&map, &route, lb2);
        d.cruise(0.0, 100.0, 8.0, |_| -1.75, no_lights);
        let at = DVec3::new(100.0, -1.75, 0.0);
        d.scorer.scenario_timed_out(d.t, "Scenario6", at);
        d.cruise(100.0, 260.0, 8.0, |_| -1.75, no_lights);
        assert_eq!(d.count(InfractionKind::ScenarioTimeout), 1);
        let r = d.finish();
        assert_eq!(r.status, "Completed", "not Perfect");
        assert_eq!(
            r.infractions.scenario_timeouts,
            ["Agent timed out a scenario (Scenario6)"]
        );
        assert!(close(r.scores.score_penalty, 0.7, 1e-12));
        assert!(close(r.scores.score_composed, 70.0, 1e-9));
        assert!(
            !r.meta.bench2drive.unwrap().success,
            "Bench2Drive counts a timed-out scenario"
        );
    }

    #[test]
    fn completion_is_along_track_and_at_most_two_points_per_tick() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        // A 5 m lateral offset does not stop progress.
        d.step(ego_at(0.5, -6.75, 5.0), &[], &[]);
        assert!(close(d.scorer.route_completion(), 0.0, 1e-9));
        d.step(ego_at(1.5, -6.75, 5.0), &[], &[]);
        assert!(close(d.scorer.route_completion(), 0.5, 1e-9));
        // A jump of 20 m ahead only advances two points per tick.
        d.step(ego_at(21.5, -1.75, 5.0), &[], &[]);
        assert!(close(d.scorer.route_completion(), 1.5, 1e-9));
        d.step(ego_at(21.5, -1.75, 5.0), &[], &[]);
        assert!(close(d.scorer.route_completion(), 2.5, 1e-9));
        for _ in 0..20 {
            d.step(ego_at(21.5, -1.75, 5.0), &[], &[]);
        }
        // Index 21 passed (x = 21 < 21.5), index 22 not.
        assert!(close(d.scorer.route_completion(), 10.5, 1e-9));
        assert_eq!(d.end, None);
    }

    #[test]
    fn completion_needs_over_99_percent_and_within_10_m() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        d.cruise(0.0, 198.5, 10.0, |_| -1.75, no_lights);
        for _ in 0..3 {
            d.step(ego_at(198.5, -1.75, 0.5), &[], &[]);
        }
        // Index 198 of 200: exactly 99 %, not more.
        assert!(close(d.scorer.route_completion(), 99.0, 1e-9));
        assert_eq!(d.end, None);
        // Past point 199 (99.5 %) but 11 m to the side of the last point: not completed.
        d.step(ego_at(199.5, -12.75, 0.5), &[], &[]);
        assert!(close(d.scorer.route_completion(), 99.5, 1e-9));
        assert_eq!(d.end, None);
        // Back within 10 m of the target: completed, RC = 100.
        assert_eq!(
            d.step(ego_at(199.5, -3.0, 0.5), &[], &[]),
            Some(RouteEnd::Completed)
        );
        assert_eq!(d.scorer.route_completion(), 100.0);
    }

    // ---------------------------------------------------------------------------------------------
    // Collisions

    fn hit(id: u32, class: CollisionClass, x: f64) -> CollisionEvent {
        CollisionEvent {
            other_id: id,
            class,
            location: DVec3::new(x, -1.75, 0.0),
            contact: None,
        }
    }

    #[test]
    fn each_collision_class_has_its_coefficient() {
        for (class, kind, factor) in [
            (
                CollisionClass::Pedestrian,
                InfractionKind::CollisionPedestrian,
                0.50,
            ),
            (
                CollisionClass::Vehicle,
                InfractionKind::CollisionVehicle,
                0.60,
            ),
            (
                CollisionClass::Layout,
                InfractionKind::CollisionLayout,
                0.65,
            ),
        ] {
            let map = straight_map();
            let route = straight_route(&map);
            let mut d = Drive::new(&map, &route);
            d.cruise(0.0, 50.0, 10.0, |_| -1.75, no_lights);
            let id = if class == CollisionClass::Layout {
                0
            } else {
                12
            };
            d.step(ego_at(50.0, -1.75, 10.0), &[hit(id, class, 50.0)], &[]);
            d.cruise(50.5, 260.0, 10.0, |_| -1.75, no_lights);
            assert_eq!(d.count(kind), 1);
            let r = d.finish();
            assert_eq!(r.status, "Completed");
            assert!(close(r.scores.score_penalty, factor, 1e-12), "{class:?}");
            assert!(close(r.scores.score_composed, 100.0 * factor, 1e-9));
            assert_eq!(r.infractions.get(kind).len(), 1);
        }
    }

    #[test]
    fn collision_message_follows_the_leaderboard() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        let event = CollisionEvent {
            other_id: 12,
            class: CollisionClass::Vehicle,
            location: DVec3::new(20.034_56, -1.75, 0.0),
            contact: None,
        };
        d.step(ego_at(20.0, -1.75, 5.0), &[event], &[]);
        assert_eq!(
            d.scorer.infractions()[0].text,
            "Agent collided against object with type=vehicle and id=12 at (x=20.035, y=-1.75, z=0.0)"
        );
    }

    #[test]
    fn collision_with_the_same_actor_counts_once_within_5_s() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        // Collide with vehicle 12 at x = 10 and keep touching it while driving 40 m in 4 s.
        let mut x = 10.0;
        for _ in 0..80 {
            d.step(
                ego_at(x, -1.75, 10.0),
                &[hit(12, CollisionClass::Vehicle, x)],
                &[],
            );
            x += 0.5;
        }
        assert_eq!(d.count(InfractionKind::CollisionVehicle), 1);
        // 6 s after the first contact and 40+ m away: the same id counts again.
        for _ in 0..40 {
            d.step(ego_at(x, -1.75, 10.0), &[], &[]);
            x += 0.5;
        }
        d.step(
            ego_at(x, -1.75, 10.0),
            &[hit(12, CollisionClass::Vehicle, x)],
            &[],
        );
        assert_eq!(d.count(InfractionKind::CollisionVehicle), 2);
        assert!(close(d.scorer.infraction_score(), 0.36, 1e-12));
    }

    #[test]
    fn collision_location_memory_blocks_repeats_until_the_ego_leaves() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        d.step(
            ego_at(10.0, -1.75, 1.0),
            &[hit(12, CollisionClass::Vehicle, 10.0)],
            &[],
        );
        // After the id expired (> 5 s), but still within 3 m of the stored location: ignored.
        for _ in 0..110 {
            d.step(ego_at(11.0, -1.75, 0.0), &[], &[]);
        }
        d.step(
            ego_at(12.0, -1.75, 1.0),
            &[hit(12, CollisionClass::Vehicle, 12.0)],
            &[],
        );
        assert_eq!(d.count(InfractionKind::CollisionVehicle), 1);
        // A different actor within 3 m: ignored as well.
        d.step(
            ego_at(12.5, -1.75, 1.0),
            &[hit(13, CollisionClass::Vehicle, 12.5)],
            &[],
        );
        assert_eq!(d.count(InfractionKind::CollisionVehicle), 1);
        // Leave (> 5 m away, the location is forgotten), come back: a new contact counts.
        d.step(ego_at(16.0, -1.75, 1.0), &[], &[]);
        d.step(
            ego_at(12.0, -1.75, 1.0),
            &[hit(13, CollisionClass::Vehicle, 12.0)],
            &[],
        );
        assert_eq!(d.count(InfractionKind::CollisionVehicle), 2);
    }

    #[test]
    fn static_layout_repeats_at_different_places() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        // Scraping a wall (id 0) every tick from x = 10 to 20: the id never blocks, the 3 m
        // location memory does, so one event per 3+ m of wall.
        let mut x = 10.0;
        while x <= 20.0 {
            d.step(
                ego_at(x, -1.75, 10.0),
                &[hit(0, CollisionClass::Layout, x)],
                &[],
            );
            x += 0.5;
        }
        // Events at x = 10, 13.5, 17 (each first point more than 3 m from the previous one).
        assert_eq!(d.count(InfractionKind::CollisionLayout), 3);
        let xs: Vec<f64> = d
            .scorer
            .infractions()
            .iter()
            .map(|i| i.location.x)
            .collect();
        assert_eq!(xs, vec![10.0, 13.5, 17.0]);
    }

    // ---------------------------------------------------------------------------------------------
    // Red lights

    fn light_states(map: &Map, controlled: LightState) -> Vec<LightState> {
        let id = light_of(map).id;
        (0..map.lights.len())
            .map(|i| {
                if i == id {
                    controlled
                } else {
                    LightState::Green
                }
            })
            .collect()
    }

    #[test]
    fn running_a_red_light_costs_070_once() {
        let map = junction_map(TRAFFIC_LIGHT);
        let route = junction_route(&map);
        let red = light_states(&map, LightState::Red);
        let mut d = Drive::new(&map, &route);
        assert_eq!(
            d.cruise(0.0, 300.0, 10.0, |_| -1.75, |_| red.clone()),
            Some(RouteEnd::Completed)
        );
        assert_eq!(d.count(InfractionKind::RedLight), 1);
        let event = d
            .scorer
            .infractions()
            .iter()
            .find(|i| i.kind == InfractionKind::RedLight)
            .unwrap();
        let id = light_of(&map).id;
        assert!(
            event
                .text
                .starts_with(&format!("Agent ran a red light {id} at (x=")),
            "{}",
            event.text
        );
        // Ours: where it was run from, in the record's events.
        let detail = event.detail.clone().unwrap();
        assert!(
            detail.starts_with("map light, lane 1 of ") && detail.contains("ego 10.0 m/s"),
            "{detail}"
        );
        let r = d.finish();
        assert!(close(r.scores.score_penalty, 0.70, 1e-12));
        assert!(close(r.scores.score_composed, 70.0, 1e-9));
        assert_eq!(r.meta.events.len(), 1);
        assert_eq!(r.meta.events[0].kind, "red_light");
        assert_eq!(r.meta.events[0].detail, detail);
    }

    #[test]
    fn a_red_light_says_what_the_agents_frames_last_showed_of_its_lamp() {
        // The head stands 5 m before the stop line and 2.25 m right of the lane (as Town01 and
        // Town02 post theirs), so a front camera loses it before the car reaches the line.
        let map = junction_map(TRAFFIC_LIGHT);
        let route = junction_route(&map);
        let head = light_of(&map).head;
        let (green, red) = (
            light_states(&map, LightState::Green),
            light_states(&map, LightState::Red),
        );
        let front = Rig::tcp_small();
        let in_frame =
            |x: f64| front.sees([(head.x - x) as f32, (head.y + 1.75) as f32, head.z as f32]);
        let gone = (500..1000)
            .map(|i| f64::from(i) * 0.1)
            .find(|&x| !in_frame(x))
            .unwrap();
        assert!(
            in_frame(50.0) && gone < 96.0,
            "the lamp leaves the frame at x = {gone}"
        );
        // Drives through with the light red from `x_red` on, the scorer told what `rig` frames.
        let detail = |x_red: f64, rig: &Rig| {
            let mut d = Drive::new(&map, &route);
            let mut x = 0.0;
            while x < 300.0 && d.end.is_none() {
                let (ego, lights) = (
                    ego_at(x, -1.75, 10.0),
                    if x < x_red { &green } else { &red },
                );
                d.scorer.frame_lamps(d.t, &ego, lights, rig);
                d.step(ego, &[], lights);
                x += 10.0 * DT;
            }
            let event = d
                .scorer
                .infractions()
                .iter()
                .find(|i| i.kind == InfractionKind::RedLight);
            event
                .and_then(|e| e.detail.clone())
                .expect("a red light was run")
        };
        let seen = detail(0.0, &front);
        assert!(
            seen.starts_with("map light, lamp last in frame red, "),
            "{seen}"
        );
        // Red only once the lamp had left the frame: the agent last saw it green, the time from
        // that tick to the tail crossing the line (x = 103.45) before.
        let blind = detail(gone + 1.0, &front);
        let rest = blind
            .strip_prefix("map light, lamp last in frame green, ")
            .unwrap_or_else(|| panic!("{blind}"));
        let age: f64 = rest.split(" s before").next().unwrap().parse().unwrap();
        let expected = (103.45 - gone) / 10.0;
        assert!(
            (age - expected).abs() <= 0.15,
            "{blind}: expected about {expected:.1} s"
        );
        assert!(blind.ends_with("ego 10.0 m/s"), "{blind}");
        // A narrow camera looking down at the road never frames it.
        let down = Rig {
            cameras: vec![CameraSpec {
                pitch: -80.0,
                fov: 30.0,
                ..front.cameras[0].clone()
            }],
        };
        let never = detail(0.0, &down);
        assert!(
            never.starts_with("map light, lamp never in frame, lane 1 of "),
            "{never}"
        );
    }

    #[test]
    fn yellow_is_not_penalised() {
        let map = junction_map(TRAFFIC_LIGHT);
        let route = junction_route(&map);
        let yellow = light_states(&map, LightState::Yellow);
        let mut d = Drive::new(&map, &route);
        d.cruise(0.0, 300.0, 10.0, |_| -1.75, |_| yellow.clone());
        assert_eq!(d.count(InfractionKind::RedLight), 0);
        assert_eq!(d.finish().scores.score_penalty, 1.0);
    }

    #[test]
    fn red_after_the_tail_passed_the_line_is_not_penalised() {
        let map = junction_map(TRAFFIC_LIGHT);
        let route = junction_route(&map);
        let green = light_states(&map, LightState::Green);
        let red = light_states(&map, LightState::Red);
        // The tail probe (3.45 m behind the centre) clears the line at x = 103.45.
        // Drive through with the light turning red once the ego centre passes `x_red`.
        let red_lights_when_red_from = |x_red: f64| {
            let mut d = Drive::new(&map, &route);
            d.cruise(
                0.0,
                300.0,
                10.0,
                |_| -1.75,
                |x| {
                    if x < x_red {
                        green.clone()
                    } else {
                        red.clone()
                    }
                },
            );
            d.count(InfractionKind::RedLight)
        };
        assert_eq!(red_lights_when_red_from(103.5), 0);
        // Turning red just before the tail crossed: penalised.
        assert_eq!(red_lights_when_red_from(101.0), 1);
    }

    #[test]
    fn stopping_at_a_red_light_is_not_penalised() {
        let map = junction_map(TRAFFIC_LIGHT);
        let route = junction_route(&map);
        let green = light_states(&map, LightState::Green);
        let red = light_states(&map, LightState::Red);
        let mut d = Drive::new(&map, &route);
        d.cruise(0.0, 97.0, 10.0, |_| -1.75, |_| red.clone());
        for _ in 0..100 {
            d.step(ego_at(97.0, -1.75, 0.0), &[], &red);
        }
        d.cruise(97.0, 300.0, 10.0, |_| -1.75, |_| green.clone());
        assert_eq!(d.end, Some(RouteEnd::Completed));
        assert_eq!(d.count(InfractionKind::RedLight), 0);
    }

    #[test]
    fn worked_check_vehicle_collision_and_red_light_give_ds_42() {
        let map = junction_map(TRAFFIC_LIGHT);
        let route = junction_route(&map);
        let red = light_states(&map, LightState::Red);
        let mut d = Drive::new(&map, &route);
        d.cruise(0.0, 50.0, 10.0, |_| -1.75, |_| red.clone());
        d.step(
            ego_at(50.0, -1.75, 10.0),
            &[hit(7, CollisionClass::Vehicle, 50.0)],
            &red,
        );
        d.cruise(50.5, 300.0, 10.0, |_| -1.75, |_| red.clone());
        let r = d.finish();
        assert_eq!(r.status, "Completed");
        assert_eq!(r.scores.score_route, 100.0);
        assert!(close(r.scores.score_penalty, 0.42, 1e-12));
        assert!(close(r.scores.score_composed, 42.0, 1e-9));
    }

    // ---------------------------------------------------------------------------------------------
    // Stop signs

    #[test]
    fn rolling_through_a_stop_costs_080() {
        let map = junction_map(STOP_SIGN);
        let route = junction_route(&map);
        let mut d = Drive::new(&map, &route);
        assert_eq!(
            d.cruise(0.0, 300.0, 10.0, |_| -1.75, no_lights),
            Some(RouteEnd::Completed)
        );
        assert_eq!(d.count(InfractionKind::StopSign), 1);
        let event = d
            .scorer
            .infractions()
            .iter()
            .find(|i| i.kind == InfractionKind::StopSign)
            .unwrap();
        assert!(
            event.text.starts_with("Agent ran a stop with id=0 at (x="),
            "{}",
            event.text
        );
        // Emitted once the ego left the sign's influence, past the stop line.
        assert!(event.time > 10.0, "at {}", event.time);
        let r = d.finish();
        assert!(close(r.scores.score_penalty, 0.80, 1e-12));
        assert_eq!(r.infractions.stop_infraction.len(), 1);
    }

    #[test]
    fn stopping_at_a_stop_sign_is_not_penalised() {
        let map = junction_map(STOP_SIGN);
        let route = junction_route(&map);
        let mut d = Drive::new(&map, &route);
        d.cruise(0.0, 97.0, 10.0, |_| -1.75, no_lights);
        for _ in 0..20 {
            d.step(ego_at(97.0, -1.75, 0.0), &[], &[]);
        }
        d.cruise(97.0, 300.0, 10.0, |_| -1.75, no_lights);
        assert_eq!(d.end, Some(RouteEnd::Completed));
        assert_eq!(d.count(InfractionKind::StopSign), 0);
        assert_eq!(d.finish().scores.score_penalty, 1.0);
    }

    // ---------------------------------------------------------------------------------------------
    // Outside route lanes

    #[test]
    fn driving_a_fifth_of_the_route_off_the_lanes_costs_a_fifth() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        // 3 m beyond the road's south edge (y = -9.5 - 3) from x = 80 to 120: 40 m of 200.
        let lateral = |x: f64| {
            if (80.0..120.0).contains(&x) {
                -12.5
            } else {
                -1.75
            }
        };
        assert_eq!(
            d.cruise(0.0, 260.0, 10.0, lateral, no_lights),
            Some(RouteEnd::Completed)
        );
        assert!(
            close(d.scorer.infraction_score(), 1.0, 0.0),
            "no factor before the end"
        );
        let (r, events) = d
            .scorer
            .finish_with_infractions(None, "RouteScenario_0", 0, 26.0, 1.0);
        let off = events
            .iter()
            .find(|i| i.kind == InfractionKind::OutsideRouteLanes)
            .unwrap();
        assert!(close(off.factor, r.scores.score_penalty, 1e-12));
        assert_eq!(r.infractions.outside_route_lanes.len(), 1);
        assert!(
            r.infractions.outside_route_lanes[0]
                .starts_with("Agent went outside its route lanes for about 40.0 meters ("),
            "{}",
            r.infractions.outside_route_lanes[0]
        );
        assert!(
            close(r.scores.score_penalty, 0.80, 0.008),
            "IS {}",
            r.scores.score_penalty
        );
        assert!(close(
            r.scores.score_composed,
            100.0 * r.scores.score_penalty,
            1e-9
        ));
        assert!(
            !r.meta.bench2drive.unwrap().success,
            "an off-lane stretch is an infraction: no Bench2Drive success"
        );
    }

    #[test]
    fn parking_lanes_and_adjacent_lanes_are_not_outside() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        // The neighbour lane -2 (y = -5.25), then along the parking lane's outer half (y = -8.75)
        // between x = 40 and 80.
        let lateral = |x: f64| {
            if (20.0..40.0).contains(&x) {
                -5.25
            } else if (40.0..80.0).contains(&x) {
                -8.75
            } else {
                -1.75
            }
        };
        d.cruise(0.0, 260.0, 10.0, lateral, no_lights);
        let r = d.finish();
        assert!(
            r.infractions.outside_route_lanes.is_empty(),
            "{:?}",
            r.infractions
        );
        assert_eq!(r.scores.score_penalty, 1.0);
    }

    #[test]
    fn driving_against_the_traffic_counts_as_outside_route_lanes() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        // On the opposite lane 1 (y = +1.75) from x = 100 to 150: 50 m of 200.
        let lateral = |x: f64| {
            if (100.0..150.0).contains(&x) {
                1.75
            } else {
                -1.75
            }
        };
        d.cruise(0.0, 260.0, 10.0, lateral, no_lights);
        let (r, events) = d
            .scorer
            .finish_with_infractions(None, "RouteScenario_0", 0, 26.0, 1.0);
        let off = events
            .iter()
            .find(|i| i.kind == InfractionKind::OutsideRouteLanes)
            .unwrap();
        assert!(close(off.factor, r.scores.score_penalty, 1e-12));
        assert_eq!(r.infractions.outside_route_lanes.len(), 1);
        assert!(
            close(r.scores.score_penalty, 0.75, 0.01),
            "IS {}",
            r.scores.score_penalty
        );
    }

    // ---------------------------------------------------------------------------------------------
    // Route deviation, blocked, timeout

    #[test]
    fn leaving_the_route_by_30_m_ends_it_without_penalty() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        d.cruise(0.0, 60.0, 10.0, |_| -1.75, no_lights);
        assert_eq!(
            d.step(ego_at(59.5, -31.8, 10.0), &[], &[]),
            Some(RouteEnd::Deviated)
        );
        let r = d.finish();
        assert_eq!(r.status, "Failed - Agent deviated from the route");
        assert_eq!(r.scores.score_penalty, 1.0);
        assert_eq!(r.infractions.route_dev.len(), 1);
        assert!(r.infractions.route_dev[0].starts_with("Agent deviated from the route at (x=59.5"));
        assert!(close(r.scores.score_route, 29.5, 1e-9));
        assert!(close(r.scores.score_composed, 29.5, 1e-9));
    }

    #[test]
    fn driving_beside_the_route_for_over_30_percent_is_a_deviation() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        // 20 m beside the route (between 15 and 30 m) from x = 10 on.
        let end = d.cruise(
            0.0,
            200.0,
            10.0,
            |x| if x < 10.0 { -1.75 } else { -21.75 },
            no_lights,
        );
        assert_eq!(end, Some(RouteEnd::Deviated));
        // The out-of-route sum passes 60 m (30 % of 200 m) at about x = 71.
        let x = d
            .scorer
            .infractions()
            .iter()
            .find(|i| i.kind == InfractionKind::RouteDeviation)
            .unwrap()
            .location
            .x;
        assert!((70.0..=72.5).contains(&x), "deviated at x = {x}");
        assert_eq!(d.finish().status, "Failed - Agent deviated from the route");
    }

    #[test]
    fn standing_still_for_more_than_180_s_blocks_the_agent() {
        let map = straight_map();
        let route = straight_route(&map);
        let config = ScoringConfig {
            timeout: Some(1000.0),
            ..ScoringConfig::default()
        };
        let mut d = Drive::with(&map, &route, config);
        d.cruise(0.0, 20.0, 10.0, |_| -1.75, no_lights);
        let stop_time = d.t;
        let mut end = None;
        let mut blocked_at = 0.0;
        while end.is_none() {
            blocked_at = d.t;
            end = d.step(ego_at(20.0, -1.75, 0.05), &[], &[]);
            if d.t - stop_time < 179.0 {
                assert_eq!(end, None);
            }
        }
        assert_eq!(end, Some(RouteEnd::Blocked));
        // Last moving tick at stop_time - DT; blocked on the first tick more than 180 s later.
        let last_moving = stop_time - DT;
        assert!(blocked_at - last_moving > 180.0 && blocked_at - last_moving <= 180.0 + DT + 1e-9);
        let r = d.finish();
        assert_eq!(r.status, "Failed - Agent got blocked");
        assert_eq!(r.scores.score_penalty, 1.0);
        assert!(
            r.infractions.vehicle_blocked[0].starts_with("Agent got blocked at (x=20.0, y=-1.75")
        );
        // Point 20 lies at x = 20, not behind the ego: RC = 19 / 200.
        assert!(close(r.scores.score_route, 9.5, 1e-9));
    }

    #[test]
    fn the_route_times_out_per_the_lb10_formula() {
        let map = straight_map();
        let route = straight_route(&map);
        assert!(close(route.length(), 200.0, 1e-6));
        let d = Drive::new(&map, &route);
        assert_eq!(d.scorer.timeout_seconds(), 165.0);
        assert_eq!(
            route_timeout(route.length(), &ScoringConfig::default()),
            165.0
        );
        drop(d);

        // Creep at 0.2 m/s (never blocked): the route times out at t = 165 s, not before.
        let mut d = Drive::new(&map, &route);
        let mut x = 0.0;
        let mut ended_at = None;
        for tick in 0..4000 {
            let t = tick as f64 * DT;
            if let Some(end) = d.step(ego_at(x, -1.75, 0.2), &[], &[]) {
                assert_eq!(end, RouteEnd::TimedOut);
                ended_at = Some(t);
                break;
            }
            x += 0.2 * DT;
        }
        let ended_at = ended_at.expect("timed out");
        assert!(close(ended_at, 165.0, 1e-6), "ended at {ended_at}");
        let r = d.finish();
        assert_eq!(r.status, "Failed - Agent timed out");
        assert_eq!(
            r.infractions.route_timeout,
            vec!["Route timeout.".to_string()]
        );
        assert_eq!(r.scores.score_penalty, 1.0);
    }

    #[test]
    fn a_users_fixed_timeout_stops_the_run_without_an_infraction() {
        let map = straight_map();
        let route = straight_route(&map);
        let config = ScoringConfig {
            timeout: Some(5.0),
            ..ScoringConfig::default()
        };
        let mut d = Drive::with(&map, &route, config);
        let mut x = 0.0;
        let mut end = None;
        for _ in 0..400 {
            end = d.step(ego_at(x, -1.75, 5.0), &[], &[]);
            if end.is_some() {
                break;
            }
            x += 5.0 * DT;
        }
        assert_eq!(end, Some(RouteEnd::Stopped));
        let r = d.finish();
        assert_eq!(r.status, "Stopped - --timeout reached");
        assert!(r.infractions.route_timeout.is_empty());
        assert_eq!(r.meta.stopped_at_s, Some(5.0));
        assert_eq!(r.scores.score_penalty, 1.0);
        assert!(!r.status.contains("Agent"), "not an agent error");
    }

    #[test]
    fn a_timeout_reported_by_the_caller_is_recorded() {
        let map = straight_map();
        let route = straight_route(&map);
        let mut d = Drive::new(&map, &route);
        d.cruise(0.0, 30.0, 10.0, |_| -1.75, no_lights);
        let r = d
            .scorer
            .finish(Some(RouteEnd::TimedOut), "RouteScenario_3", 3, 3.0, 1.0);
        assert_eq!(r.status, "Failed - Agent timed out");
        assert_eq!(r.infractions.route_timeout.len(), 1);
        assert_eq!((r.route_id.as_str(), r.index), ("RouteScenario_3", 3));
    }
}
