//! The Rerun recording of a study, read back with Rerun's own decoder.

mod common;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;

use re_log_types::{LogMsg, StoreKind};

/// Rows and timelines logged per entity path of the recording store.
#[derive(Debug, Default)]
struct Entity {
    rows: usize,
    timelines: Vec<String>,
}

fn read(path: &std::path::Path) -> (BTreeMap<String, Entity>, bool) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut entities: BTreeMap<String, Entity> = BTreeMap::new();
    let mut blueprint = false;
    for msg in re_log_encoding::DecoderApp::decode_eager(file).unwrap() {
        let msg = msg.unwrap();
        match &msg {
            LogMsg::ArrowMsg(store, arrow) if store.kind() == StoreKind::Recording => {
                let chunk = re_chunk::Chunk::from_arrow_msg(arrow).unwrap();
                let e = entities.entry(chunk.entity_path().to_string()).or_default();
                e.rows += chunk.num_rows();
                for t in chunk.timelines().keys() {
                    if !e.timelines.contains(&t.to_string()) {
                        e.timelines.push(t.to_string());
                    }
                }
            }
            LogMsg::ArrowMsg(store, _) if store.kind() == StoreKind::Blueprint => blueprint = true,
            _ => {}
        }
    }
    (entities, blueprint)
}

#[test]
fn the_recording_holds_the_cell_the_poses_the_centring_and_the_study() {
    let tmp = common::scratch("recording");
    let dir = tmp.path();
    let out = Command::new(env!("CARGO_BIN_EXE_calsim"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", "scenarios/ci_quick.toml", "--set-sizes", "20:75:55", "--repetitions", "3", "--no-plots", "--out"])
        .arg(dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let path: PathBuf = dir.join("ci_quick/study.rrd");
    let (entities, blueprint) = read(&path);
    assert!(blueprint, "no blueprint in the file");
    let rows =
        |p: &str| entities.get(p).map(|e| e.rows).unwrap_or_else(|| panic!("{p} missing from {:?}", entities.keys().collect::<Vec<_>>()));
    let timelines = |p: &str| entities.get(p).map(|e| e.timelines.clone()).unwrap_or_default();

    // Static cell.
    for p in [
        "/cell/spheres",
        "/cell/solids/risers",
        "/cell/solids/boxes",
        "/cell/tracker",
        "/cell/frames/world",
        "/cell/frames/base",
        "/pool/tcp",
    ] {
        assert!(rows(p) >= 1, "{p}");
    }
    // The robot at each of the 360 pool configurations and the 506 validation poses.
    assert_eq!(rows("/pool/robot"), 360);
    assert!(timelines("/pool/robot").contains(&"pool_configuration".to_string()));
    assert_eq!(rows("/validation/robot"), 506);
    assert!(timelines("/validation/robot").contains(&"validation_pose".to_string()));
    // Centring readings: at least one reading per pool configuration and indicator (plus the static series style).
    for axis in ["x", "y", "z"] {
        let n = rows(&format!("/pool/centring/{axis}"));
        assert!(n > 360, "{axis}: {n} rows");
    }
    // Errors before and after calibration, and the error vectors.
    for p in ["/validation/before", "/validation/after", "/validation/error_vectors"] {
        assert!(rows(p) >= 1, "{p}");
    }
    // One scalar per task (2 set sizes x 3 repetitions) plus the series style.
    for p in ["/study/validation_mean_mm", "/study/validation_max_mm", "/study/o1"] {
        assert_eq!(rows(p), 6 + 1, "{p}");
        assert!(timelines(p).contains(&"set_size".to_string()), "{p}: {:?}", timelines(p));
    }
}

#[test]
fn the_spms_recording_holds_the_heads_the_pool_the_test_and_the_study() {
    let tmp = common::scratch("recording-spms");
    let dir = tmp.path();
    let out = Command::new(env!("CARGO_BIN_EXE_calsim"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["run", "scenarios/er20c10_spms.toml", "--set-sizes", "20:50:30", "--repetitions", "2", "--no-plots", "--out"])
        .arg(dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (entities, blueprint) = read(&dir.join("er20c10_spms/study.rrd"));
    assert!(blueprint, "no blueprint in the file");
    let rows =
        |p: &str| entities.get(p).map(|e| e.rows).unwrap_or_else(|| panic!("{p} missing from {:?}", entities.keys().collect::<Vec<_>>()));
    let timelines = |p: &str| entities.get(p).map(|e| e.timelines.clone()).unwrap_or_default();
    // Three stations, each head with its beams and frame.
    for k in 0..3 {
        assert!(rows(&format!("/cell/heads/{k}/beams")) >= 1 && rows(&format!("/cell/heads/{k}/frame")) >= 1, "head {k}");
    }
    assert!(rows("/cell/frames/base") >= 1 && rows("/pool/sphere") >= 1);
    // The arm at each of the 300 pool configurations, with the measuring error (plus the series style).
    assert_eq!(rows("/pool/robot"), 300);
    assert!(timelines("/pool/robot").contains(&"pool_configuration".to_string()));
    assert_eq!(rows("/pool/measuring_error_um"), 300 + 1);
    for p in ["/iso9283/cube", "/iso9283/before", "/iso9283/after"] {
        assert!(rows(p) >= 1, "{p}");
    }
    // Per selection, one value per task (2 sizes x 2 repetitions) plus the series style.
    for sel in ["random", "detmax"] {
        for p in ["ap_mean_mm", "ap_max_mm", "o1"] {
            let path = format!("/study/{sel}/{p}");
            assert_eq!(rows(&path), 4 + 1, "{path}");
            assert!(timelines(&path).contains(&"set_size".to_string()), "{path}");
        }
    }
}
