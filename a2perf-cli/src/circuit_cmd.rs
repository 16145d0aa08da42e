//! `a2perf circuit`: placement cost, netlist generation and placement pictures.

use std::path::{Path, PathBuf};

use a2perf_circuit::render::render_svg;
use a2perf_circuit::{
    CostSettings, GeneratorConfig, Netlist, Placement, PlacementCost, SoftMacroRule, generate,
};
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use serde::Serialize;

/// Arguments of `a2perf circuit`.
#[derive(Args, Debug)]
pub struct CircuitArgs {
    #[command(subcommand)]
    command: CircuitCommand,
}

#[derive(Subcommand, Debug)]
enum CircuitCommand {
    /// Compute wirelength, density, congestion and proxy cost of a placement.
    Cost {
        #[command(flatten)]
        input: InputArgs,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Write a generated netlist (`netlist.pb.txt`) and initial placement (`initial.plc`).
    Generate {
        /// Size preset.
        #[arg(long, value_enum, default_value_t = Preset::Small)]
        preset: Preset,
        /// Generator seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Override the number of hard macros.
        #[arg(long)]
        hard_macros: Option<usize>,
        /// Override the number of soft macros.
        #[arg(long)]
        soft_macros: Option<usize>,
        /// Override the number of ports.
        #[arg(long)]
        ports: Option<usize>,
        /// Override the canvas `W,H` (µm).
        #[arg(long, value_parser = parse_pair_f64)]
        canvas: Option<(f64, f64)>,
        /// Override the grid `COLS,ROWS`.
        #[arg(long, value_parser = parse_pair_usize)]
        grid: Option<(usize, usize)>,
        /// Name of the circuit.
        #[arg(long)]
        name: Option<String>,
        /// Output directory.
        #[arg(short = 'o', long)]
        output: PathBuf,
    },
    /// Draw a placement as SVG: macros, soft macros, ports and the congestion heatmap.
    Render {
        #[command(flatten)]
        input: InputArgs,
        /// Pixels on the longer canvas side.
        #[arg(long, default_value_t = 800.0)]
        size: f64,
        /// Output SVG file.
        #[arg(short = 'o', long)]
        output: PathBuf,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Preset {
    Small,
    Medium,
    Ariane,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Rule {
    /// Soft iff the name starts with `Grp` (Google).
    NamePrefix,
    /// Soft iff the type is lower-case `macro` (plc_client_os).
    TypeCase,
}

#[derive(Args, Debug)]
struct InputArgs {
    /// circuit_training netlist (`.pb.txt`, optionally gzipped).
    #[arg(long)]
    netlist: PathBuf,
    /// Placement (`.plc`); settings in its header are used. Without it, netlist coordinates.
    #[arg(long)]
    placement: Option<PathBuf>,
    /// Canvas `W,H` (µm).
    #[arg(long, value_parser = parse_pair_f64)]
    canvas: Option<(f64, f64)>,
    /// Placement grid `COLS,ROWS`.
    #[arg(long, value_parser = parse_pair_usize)]
    grid: Option<(usize, usize)>,
    /// Routing tracks per µm `H,V`.
    #[arg(long, value_parser = parse_pair_f64)]
    routes_per_micron: Option<(f64, f64)>,
    /// Tracks used per µm of hard macro `H,V`.
    #[arg(long, value_parser = parse_pair_f64)]
    macro_routing_alloc: Option<(f64, f64)>,
    /// Congestion smoothing range.
    #[arg(long)]
    smooth_range: Option<f64>,
    /// Make soft macros square (as the CT environment does).
    #[arg(long)]
    square_soft_macros: bool,
    /// Separate congestion grid `COLS,ROWS` (semantics assumed; default: the placement grid).
    #[arg(long, value_parser = parse_pair_usize)]
    congestion_grid: Option<(usize, usize)>,
    /// Proxy weights `WIRELENGTH,DENSITY,CONGESTION`.
    #[arg(long, value_parser = parse_triple_f64)]
    weights: Option<(f64, f64, f64)>,
    /// Hard/soft macro classification.
    #[arg(long, value_enum, default_value_t = Rule::NamePrefix)]
    soft_macro_rule: Rule,
}

fn parse_nums(s: &str, n: usize) -> std::result::Result<Vec<f64>, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .map_err(|_| format!("`{t}` is not a number"))
        })
        .collect::<std::result::Result<_, _>>()?;
    if v.len() != n {
        return Err(format!("expected {n} comma-separated numbers, got `{s}`"));
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(format!("`{s}`: numbers must be finite"));
    }
    Ok(v)
}

fn parse_pair_f64(s: &str) -> std::result::Result<(f64, f64), String> {
    let v = parse_nums(s, 2)?;
    Ok((v[0], v[1]))
}

fn parse_triple_f64(s: &str) -> std::result::Result<(f64, f64, f64), String> {
    let v = parse_nums(s, 3)?;
    Ok((v[0], v[1], v[2]))
}

fn parse_pair_usize(s: &str) -> std::result::Result<(usize, usize), String> {
    let v = parse_nums(s, 2)?;
    if v.iter().any(|x| *x < 1.0 || x.fract() != 0.0 || *x > 1e6) {
        return Err(format!("`{s}`: expected two positive integers"));
    }
    Ok((v[0] as usize, v[1] as usize))
}

struct Loaded {
    netlist: Netlist,
    cost: PlacementCost,
}

fn load(input: &InputArgs) -> Result<Loaded> {
    let rule = match input.soft_macro_rule {
        Rule::NamePrefix => SoftMacroRule::NamePrefix,
        Rule::TypeCase => SoftMacroRule::TypeCase,
    };
    let netlist = Netlist::from_file(&input.netlist, rule)
        .with_context(|| "cannot read the netlist".to_string())?;
    let plc = match &input.placement {
        Some(p) => Some(Placement::from_file(p).context("cannot read the placement")?),
        None => None,
    };
    let header = plc.as_ref().map(|p| p.header.clone()).unwrap_or_default();
    let mut s = CostSettings::from_header(&netlist, &header);
    if let Some((w, h)) = input.canvas {
        (s.canvas_width, s.canvas_height) = (w, h);
    }
    if let Some((c, r)) = input.grid {
        (s.grid_cols, s.grid_rows) = (c, r);
    }
    if let Some((h, v)) = input.routes_per_micron {
        (s.hroutes_per_micron, s.vroutes_per_micron) = (h, v);
    }
    if let Some((h, v)) = input.macro_routing_alloc {
        (s.hrouting_alloc, s.vrouting_alloc) = (h, v);
    }
    if let Some(k) = input.smooth_range {
        s.smooth_range = k;
    }
    s.make_soft_macros_square = input.square_soft_macros;
    s.congestion_grid = input.congestion_grid;
    if let Some((a, b, c)) = input.weights {
        s.weights = a2perf_circuit::CostWeights {
            wirelength: a,
            density: b,
            congestion: c,
        };
    }
    let mut cost = PlacementCost::new(&netlist, s)?;
    if let (Some(p), Some(path)) = (&plc, &input.placement) {
        cost.apply_placement(p)
            .with_context(|| format!("{}: placement does not fit the netlist", path.display()))?;
    }
    Ok(Loaded { netlist, cost })
}

#[derive(Serialize)]
struct CostReport {
    netlist: String,
    netlist_hash: String,
    placement: Option<String>,
    settings: CostSettings,
    wirelength: f64,
    net_count: f64,
    wirelength_cost: f64,
    density_cost: f64,
    congestion_cost: f64,
    h_congestion_cost: f64,
    v_congestion_cost: f64,
    proxy_cost: f64,
    compute_ms: f64,
}

/// Runs `a2perf circuit …`.
pub fn run(args: &CircuitArgs) -> Result<()> {
    match &args.command {
        CircuitCommand::Cost { input, json } => {
            let Loaded { netlist, mut cost } = load(input)?;
            let t = std::time::Instant::now();
            cost.recompute();
            let c = cost.costs();
            let compute_ms = t.elapsed().as_secs_f64() * 1e3;
            let r = CostReport {
                netlist: netlist.name.clone(),
                netlist_hash: netlist.content_hash.clone(),
                placement: input.placement.as_ref().map(|p| p.display().to_string()),
                settings: cost.settings().clone(),
                wirelength: c.wirelength,
                net_count: c.net_count,
                wirelength_cost: c.wirelength_cost,
                density_cost: c.density_cost,
                congestion_cost: c.congestion_cost,
                h_congestion_cost: c.h_congestion_cost,
                v_congestion_cost: c.v_congestion_cost,
                proxy_cost: c.proxy_cost,
                compute_ms,
            };
            if *json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                let s = &r.settings;
                println!("netlist          {} ({})", r.netlist, r.netlist_hash);
                println!(
                    "canvas           {} x {}  grid {} x {}  routes {}/{}  alloc {}/{}  smooth {}",
                    s.canvas_width,
                    s.canvas_height,
                    s.grid_cols,
                    s.grid_rows,
                    s.hroutes_per_micron,
                    s.vroutes_per_micron,
                    s.hrouting_alloc,
                    s.vrouting_alloc,
                    s.smooth_range
                );
                println!("wirelength       {}", r.wirelength);
                println!("wirelength cost  {}", r.wirelength_cost);
                println!("density cost     {}", r.density_cost);
                println!("congestion cost  {}", r.congestion_cost);
                println!(
                    "proxy cost       {}  (weights {}/{}/{})",
                    r.proxy_cost, s.weights.wirelength, s.weights.density, s.weights.congestion
                );
                println!("computed in      {:.3} ms", r.compute_ms);
            }
            Ok(())
        }
        CircuitCommand::Generate {
            preset,
            seed,
            hard_macros,
            soft_macros,
            ports,
            canvas,
            grid,
            name,
            output,
        } => {
            let mut cfg = match preset {
                Preset::Small => GeneratorConfig::small(),
                Preset::Medium => GeneratorConfig::medium(),
                Preset::Ariane => GeneratorConfig::ariane_scale(),
            };
            if let Some(n) = hard_macros {
                if *n == 0 {
                    bail!("--hard-macros must be at least 1");
                }
                cfg.num_hard_macros = *n;
            }
            if let Some(n) = soft_macros {
                cfg.num_soft_macros = *n;
            }
            if let Some(n) = ports {
                cfg.num_ports = *n;
            }
            if let Some((w, h)) = canvas {
                if *w <= 0.0 || *h <= 0.0 {
                    bail!("--canvas must be positive");
                }
                cfg.canvas = (*w, *h);
            }
            if let Some(g) = grid {
                cfg.grid = *g;
            }
            if let Some(n) = name {
                cfg.name = n.clone();
            }
            let g = generate(&cfg, *seed);
            std::fs::create_dir_all(output)
                .with_context(|| format!("cannot create {}", output.display()))?;
            write(&output.join("netlist.pb.txt"), &g.netlist.to_pbtxt())?;
            write(&output.join("initial.plc"), &g.placement.to_text())?;
            println!(
                "wrote {} ({} hard macros, {} soft macros, {} ports, {} nets, hash {}) and initial.plc",
                output.join("netlist.pb.txt").display(),
                cfg.num_hard_macros,
                cfg.num_soft_macros,
                cfg.num_ports,
                g.netlist.nets.len(),
                g.netlist.content_hash
            );
            Ok(())
        }
        CircuitCommand::Render {
            input,
            size,
            output,
        } => {
            if !(size.is_finite() && *size >= 16.0 && *size <= 100_000.0) {
                bail!("--size must be between 16 and 100000 pixels");
            }
            let Loaded { netlist, mut cost } = load(input)?;
            let svg = render_svg(&mut cost, &netlist.name, *size);
            write(output, &svg)?;
            println!("wrote {}", output.display());
            Ok(())
        }
    }
}

fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}
