//! `a2perf circuit {cost, generate, render}` end to end.

use std::path::Path;
use std::process::{Command, Output};

fn a2perf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args(args)
        .output()
        .expect("the a2perf binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn json(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "stderr: {}", text(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

#[test]
fn generate_cost_render_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = a2perf(&[
        "circuit",
        "generate",
        "--preset",
        "small",
        "--seed",
        "7",
        "-o",
        d.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let netlist = d.join("netlist.pb.txt");
    let plc = d.join("initial.plc");
    assert!(netlist.exists() && plc.exists());
    let args = |extra: &[&str]| {
        let mut v = vec![
            "circuit".to_string(),
            "cost".into(),
            "--netlist".into(),
            netlist.display().to_string(),
            "--placement".into(),
            plc.display().to_string(),
            "--json".into(),
        ];
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let run = |extra: &[&str]| {
        let a = args(extra);
        json(&a2perf(&a.iter().map(String::as_str).collect::<Vec<_>>()))
    };
    let base = run(&[]);
    for k in [
        "wirelength",
        "wirelength_cost",
        "density_cost",
        "congestion_cost",
        "proxy_cost",
    ] {
        assert!(base[k].as_f64().unwrap().is_finite(), "{k}");
    }
    // Header settings: grid 16x16 from the generated .plc.
    assert_eq!(base["settings"]["grid_cols"], 16);
    let proxy = base["wirelength_cost"].as_f64().unwrap()
        + base["density_cost"].as_f64().unwrap()
        + 0.5 * base["congestion_cost"].as_f64().unwrap();
    assert!((proxy - base["proxy_cost"].as_f64().unwrap()).abs() < 1e-12);
    // Flags override the header.
    let g = run(&["--grid", "8,8", "--smooth-range", "0"]);
    assert_eq!(g["settings"]["grid_cols"], 8);
    assert_ne!(g["density_cost"], base["density_cost"]);
    let wide = run(&["--canvas", "400,400"]);
    assert!(wide["wirelength_cost"].as_f64().unwrap() < base["wirelength_cost"].as_f64().unwrap());
    // Render.
    let svg = d.join("out.svg");
    let out = a2perf(&[
        "circuit",
        "render",
        "--netlist",
        netlist.to_str().unwrap(),
        "--placement",
        plc.to_str().unwrap(),
        "-o",
        svg.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = std::fs::read_to_string(&svg).unwrap();
    assert!(s.starts_with("<svg") && s.contains("hard_macros") && s.contains("congestion"));
}

#[test]
fn bad_inputs_fail_with_named_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.pb.txt");
    std::fs::write(
        &bad,
        "node {\n  name: \"a\"\n  attr { key: \"type\" value { placeholder: \"WHAT\" } }\n}\n",
    )
    .unwrap();
    let out = a2perf(&["circuit", "cost", "--netlist", bad.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("bad.pb.txt:3") && err.contains("WHAT"),
        "{err}"
    );
    let out = a2perf(&[
        "circuit",
        "cost",
        "--netlist",
        "/nonexistent/netlist.pb.txt",
    ]);
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("/nonexistent/netlist.pb.txt"));
    let out = a2perf(&[
        "circuit",
        "cost",
        "--netlist",
        bad.to_str().unwrap(),
        "--grid",
        "0,3",
    ]);
    assert!(!out.status.success());
}

#[test]
fn shared_ng45_matches_golden() {
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit/ariane133_ng45"
    ));
    if !dir.exists() {
        if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
            panic!("A2PERF_REQUIRE_SHARED=1 but {} is missing", dir.display());
        }
        eprintln!("skipping: {} not present", dir.display());
        return;
    }
    // The legalized.plc header carries Google's settings (24x21, 57.031/56.818, 39.583/30.303,
    // smoothing 0): the golden `plc_header_google_defaults` profile.
    let out = a2perf(&[
        "circuit",
        "cost",
        "--netlist",
        dir.join("netlist.pb.txt.gz").to_str().unwrap(),
        "--placement",
        dir.join("legalized.plc").to_str().unwrap(),
        "--json",
    ]);
    let v = json(&out);
    let close = |k: &str, want: f64| {
        let got = v[k].as_f64().unwrap();
        assert!(
            (got - want).abs() <= 1e-9 * want.abs(),
            "{k}: {got} vs {want}"
        );
    };
    close("wirelength", 4763107.116961203);
    close("wirelength_cost", 0.07356822360473059);
    close("density_cost", 0.49881790637823686);
    close("congestion_cost", 0.725914889902168);
}
