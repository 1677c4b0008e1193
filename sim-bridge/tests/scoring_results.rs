//! Route records, the global record and the leaderboard 1.0 results file: averaging, infractions
//! per km, the JSON shape, round trips, malformed input and the summary table.

/// Named `scoring` so that `cargo test -p sim-bridge scoring` selects these tests.
mod scoring {

    use sim_bridge::scoring::{
        InfractionKind, Infractions, LABELS, Results, RouteMeta, RouteRecord, Scores,
        global_record, summary_table,
    };

    fn record(index: usize, rc: f64, is: f64, length: f64, status: &str) -> RouteRecord {
        RouteRecord {
            index,
            infractions: Infractions::default(),
            meta: RouteMeta {
                duration_game: 100.0,
                duration_system: 50.0,
                repetition: Some(index % 2),
                route_length: length,
                seed: Some(7),
                stopped_at_s: None,
                events: Vec::new(),
                bench2drive: None,
            },
            route_id: format!("RouteScenario_{index}"),
            scores: Scores {
                score_composed: (rc * is).max(0.0),
                score_penalty: is,
                score_route: rc,
            },
            status: status.to_string(),
        }
    }

    fn three_records() -> Vec<RouteRecord> {
        let mut a = record(0, 100.0, 0.5, 1000.0, "Completed");
        a.infractions.collisions_pedestrian.push(
            "Agent collided against object with type=walker.pedestrian and id=3 at (x=1.0, y=2.0, z=0.0)"
                .into(),
        );
        let mut b = record(1, 50.0, 1.0, 2000.0, "Failed - Agent got blocked");
        b.infractions.collisions_vehicle.push(
            "Agent collided against object with type=vehicle and id=4 at (x=1.0, y=2.0, z=0.0)"
                .into(),
        );
        b.infractions
            .vehicle_blocked
            .push("Agent got blocked at (x=5.0, y=6.0, z=0.0)".into());
        let mut c = record(2, 0.0, 0.6, 500.0, "Failed - Agent timed out");
        c.infractions
            .collisions_vehicle
            .push("Agent collided ...".into());
        c.infractions.route_timeout.push("Route timeout.".into());
        vec![a, b, c]
    }

    #[test]
    fn global_scores_are_separate_means_not_a_product_of_means() {
        let records = three_records();
        let g = global_record(&records);
        // DS: (50 + 50 + 0) / 3; RC: (100 + 50 + 0) / 3; IS: (0.5 + 1 + 0.6) / 3.
        assert!((g.scores.score_composed - 100.0 / 3.0).abs() < 1e-12);
        assert!((g.scores.score_route - 50.0).abs() < 1e-12);
        assert!((g.scores.score_penalty - 0.7).abs() < 1e-12);
        assert!(
            (g.scores.score_route * g.scores.score_penalty - g.scores.score_composed).abs() > 1.0
        );
        // Sample standard deviation (N - 1) of DS: values 50, 50, 0 around 33.33.
        let std = g.meta.scores_std.unwrap();
        assert!((std.score_composed - (2500.0f64 / 3.0).sqrt()).abs() < 1e-9);
        assert_eq!(g.meta.records, Some(3));
        assert_eq!((g.index, g.route_id), (-1, -1));
    }

    #[test]
    fn infractions_per_km_sum_the_per_route_rates_and_skip_rc_zero() {
        let g = global_record(&three_records());
        // Route 0: 1 pedestrian over 1.0 km driven; route 1: 1 vehicle over 0.5 * 2 km = 1 km;
        // route 2 has RC = 0 and is skipped.
        assert!((g.infractions.collisions_pedestrian - 1.0).abs() < 1e-12);
        assert!((g.infractions.collisions_vehicle - 1.0).abs() < 1e-12);
        assert!((g.infractions.vehicle_blocked - 1.0).abs() < 1e-12);
        assert_eq!(g.infractions.route_timeout, 0.0);
        let counts = g.meta.infraction_counts.unwrap();
        assert_eq!(counts.collisions_vehicle, 2);
        assert_eq!(counts.route_timeout, 1);
    }

    #[test]
    fn global_status_lists_the_failed_records() {
        let g = global_record(&three_records());
        assert_eq!(g.status, "Failed");
        assert_eq!(
            g.meta.exceptions,
            vec![
                (
                    "RouteScenario_1".to_string(),
                    1,
                    "Failed - Agent got blocked".to_string()
                ),
                (
                    "RouteScenario_2".to_string(),
                    2,
                    "Failed - Agent timed out".to_string()
                ),
            ]
        );
        let all_done = vec![record(0, 100.0, 1.0, 100.0, "Completed")];
        assert_eq!(global_record(&all_done).status, "Completed");
        assert!(global_record(&all_done).meta.exceptions.is_empty());
    }

    #[test]
    fn results_have_the_leaderboard_shape() {
        let results = Results::new(three_records(), 3, vec!["carla_camera".into()]);
        assert_eq!(results.checkpoint.progress, vec![3, 3]);
        assert_eq!(results.entry_status, "Finished with agent errors");
        assert!(results.eligible);
        assert_eq!(results.labels, LABELS.to_vec());
        assert_eq!(results.values.len(), 12);
        assert_eq!(results.values[0], "33.333");
        assert_eq!(results.values[1], "50.000");
        assert_eq!(results.values[2], "0.700");
        assert_eq!(results.values[3], "1.000"); // collisions with pedestrians per km
        assert_eq!(results.values[11], "1.000"); // agent blocked per km

        let json = results.to_json();
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        assert_eq!(
            keys,
            [
                "_checkpoint",
                "eligible",
                "entry_status",
                "labels",
                "sensors",
                "values"
            ]
        );
        let rec = &v["_checkpoint"]["records"][1];
        assert_eq!(rec["route_id"], "RouteScenario_1");
        assert_eq!(rec["status"], "Failed - Agent got blocked");
        assert_eq!(rec["scores"]["score_route"], 50.0);
        assert_eq!(rec["meta"]["route_length"], 2000.0);
        for kind in InfractionKind::ALL {
            assert!(rec["infractions"][kind.key()].is_array(), "{}", kind.key());
        }
        let g = &v["_checkpoint"]["global_record"];
        assert_eq!(g["route_id"], -1);
        assert_eq!(g["status"], "Failed");
        assert_eq!(g["meta"]["exceptions"][0][0], "RouteScenario_1");
        assert!(g["infractions"]["collisions_vehicle"].is_f64());
        // Python's json.dump(indent=4, sort_keys=True) layout.
        assert!(
            json.starts_with("{\n    \"_checkpoint\": {\n        \"global_record\": {"),
            "{json}"
        );

        let missing = Results::new(three_records(), 5, vec![]);
        assert_eq!(missing.entry_status, "Finished with missing data");
        assert!(!missing.eligible);
        assert_eq!(missing.checkpoint.progress, vec![3, 5]);
        let clean = Results::new(vec![record(0, 100.0, 1.0, 100.0, "Completed")], 1, vec![]);
        assert_eq!(clean.entry_status, "Finished");
    }

    #[test]
    fn results_round_trip_through_json() {
        let results = Results::new(three_records(), 3, vec!["carla_camera".into()]);
        let back = Results::from_json(&results.to_json()).expect("our own file parses");
        assert_eq!(back, results);
        assert_eq!(back.to_json(), results.to_json());
    }

    #[test]
    fn a_leaderboard_file_parses() {
        // The shape of a real LB1.0 file (TransFuser's autopilot results), trimmed.
        let text = r#"{
        "_checkpoint": {
            "global_record": {
                "index": -1,
                "infractions": {"collisions_layout": 0.0, "collisions_pedestrian": 0.0147,
                    "collisions_vehicle": 0.0638, "outside_route_lanes": 0.0, "red_light": 0.0221,
                    "route_dev": 0.0, "route_timeout": 0.0, "stop_infraction": 0.1432,
                    "vehicle_blocked": 0.3602},
                "meta": {"exceptions": [["RouteScenario_1", 1, "Failed - Agent got blocked"]]},
                "route_id": -1,
                "scores": {"score_composed": 74.487, "score_penalty": 0.8939, "score_route": 82.71},
                "status": "Failed"
            },
            "progress": [2, 2],
            "records": [
                {"index": 0,
                 "infractions": {"collisions_layout": [], "collisions_pedestrian": [
                    "Agent collided against object with type=walker.pedestrian.0026 and id=3873 at (x=20.03, y=109.45, z=0.253)"],
                    "collisions_vehicle": [], "outside_route_lanes": [], "red_light": [], "route_dev": [],
                    "route_timeout": [], "stop_infraction": [], "vehicle_blocked": []},
                 "meta": {"duration_game": 652.9, "duration_system": 745.3, "route_length": 974.08},
                 "route_id": "RouteScenario_0",
                 "scores": {"score_composed": 50.0, "score_penalty": 0.5, "score_route": 100.0},
                 "status": "Completed"},
                {"index": 1,
                 "infractions": {"collisions_layout": [], "collisions_pedestrian": [], "collisions_vehicle": [],
                    "outside_route_lanes": [], "red_light": ["Agent ran a red light 6454 at (x=249.4, y=46.07, z=0.2)"],
                    "route_dev": [], "route_timeout": [], "stop_infraction": [],
                    "vehicle_blocked": ["Agent got blocked at (x=-73.242, y=88.267, z=0.605)"]},
                 "meta": {"duration_game": 725.25, "duration_system": 1397.05, "route_length": 1869.97},
                 "route_id": "RouteScenario_1",
                 "scores": {"score_composed": 36.817, "score_penalty": 0.7, "score_route": 52.596},
                 "status": "Failed - Agent got blocked"}
            ]
        },
        "eligible": true,
        "entry_status": "Finished with agent errors",
        "labels": ["Avg. driving score", "Avg. route completion"],
        "sensors": ["carla_opendrive_map", "carla_speedometer"],
        "values": ["74.487", "82.710"]
    }"#;
        let r = Results::from_json(text).expect("LB1.0 file parses");
        assert_eq!(r.checkpoint.records.len(), 2);
        assert_eq!(
            r.checkpoint.records[1]
                .infractions
                .count(InfractionKind::RedLight),
            1
        );
        assert_eq!(r.checkpoint.records[0].meta.repetition, None);
        let g = r.checkpoint.global_record.as_ref().unwrap();
        assert_eq!(g.meta.exceptions.len(), 1);
        assert!((g.infractions.vehicle_blocked - 0.3602).abs() < 1e-12);

        // A file written before the first global record: `{}` and empty progress.
        let early = r#"{"_checkpoint": {"global_record": {}, "progress": [], "records": []},
                        "sensors": [], "values": []}"#;
        let r = Results::from_json(early).expect("fresh checkpoint parses");
        assert!(r.checkpoint.global_record.is_none());
        assert!(r.to_json().contains("\"global_record\": {}"));
    }

    #[test]
    fn malformed_json_is_a_clear_error() {
        let err = Results::from_json("{\"_checkpoint\": {\"records\": [").unwrap_err();
        let text = err.to_string();
        assert!(
            text.starts_with("malformed leaderboard results JSON:"),
            "{text}"
        );
        assert!(text.contains("line"), "{text}");

        let err = Results::from_json(r#"{"_checkpoint": {"records": 5}}"#).unwrap_err();
        assert!(err.to_string().contains("invalid type"), "{err}");

        let err = Results::from_json(r#"{"values": []}"#).unwrap_err();
        assert!(err.to_string().contains("_checkpoint"), "{err}");

        let err = Results::from_json(r#"{"_checkpoint": {"progress": [1, 2, 3]}}"#).unwrap_err();
        assert!(err.to_string().contains("progress has 3 entries"), "{err}");

        let err = Results::from_json(r#"{"_checkpoint": {}, "values": [true]}"#).unwrap_err();
        assert!(err.to_string().contains("strings or numbers"), "{err}");
    }

    #[test]
    fn summary_table_has_a_row_per_record_and_a_mean_row() {
        let results = Results::new(three_records(), 3, vec![]);
        let table = summary_table(&results);
        println!("{table}");
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 2 + 3 + 2 + 1);
        assert!(lines[0].starts_with("route"));
        assert!(lines[0].contains("DS") && lines[0].contains("ped") && lines[0].contains("blk"));
        let widths: Vec<usize> = lines[..7].iter().map(|l| l.len()).collect();
        assert!(
            widths.iter().all(|w| *w == widths[0]),
            "fixed width: {widths:?}"
        );
        assert!(lines[2].starts_with("RouteScenario_0"));
        assert!(lines[2].contains("Completed") && lines[2].contains("50.00"));
        assert!(lines[3].contains("Failed - Agent got blocked"));
        assert!(lines[6].starts_with("mean of 3"));
        assert!(
            lines[6].contains("33.33") && lines[6].contains("50.00") && lines[6].contains("0.700")
        );
        // Records written without Bench2Drive figures count as failures and add none.
        assert_eq!(
            lines[7],
            "Bench2Drive: success rate 0.00 %, efficiency -, comfort -"
        );
    }
}
