//! `spwi-sim layout`: writes a floor to a TOML file — a generated one, or the built-in
//! or a given one mirrored — so it can be read, rendered, edited and passed to any
//! tool with `--layouts FILE`. With `--plan` it writes the floor's plan instead (where
//! its stations' work spots stand), as `spwi-agent --floor-plan` reads it.

use anyhow::{bail, Result};
use spwi_world::generate;
use spwi_world::layout::Layout;

/// The arguments of `spwi-sim layout`.
#[derive(clap::Args, Debug)]
pub struct LayoutArgs {
    /// Generate the floor of this generator seed (`train:N` is seed N).
    #[arg(long, value_name = "SEED", conflicts_with = "mirror")]
    pub generate: Option<u64>,
    /// Mirror a floor (x → width − x): the built-in one, or FILE.
    #[arg(long, value_name = "FILE", num_args = 0..=1)]
    pub mirror: Option<Option<std::path::PathBuf>>,
    /// Write the floor's plan (its stations' work spots) instead of the floor: of the
    /// floor --generate or --mirror names, of FILE, or of the built-in floor.
    #[arg(long, value_name = "FILE", num_args = 0..=1)]
    pub plan: Option<Option<std::path::PathBuf>>,
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// `spwi-sim layout`.
pub fn main(a: LayoutArgs) -> Result<()> {
    if matches!(a.plan, Some(Some(_))) && (a.generate.is_some() || a.mirror.is_some()) {
        bail!("--plan FILE names the floor itself: give it no --generate or --mirror");
    }
    let layout = match (&a.generate, &a.mirror, &a.plan) {
        (Some(seed), _, _) => generate::layout(*seed),
        (None, Some(None), _) => Layout::default_layout().mirrored(),
        (None, Some(Some(p)), _) => Layout::load(p)?.mirrored(),
        (None, None, Some(Some(p))) => Layout::load(p)?,
        (None, None, Some(None)) => Layout::default_layout(),
        (None, None, None) => bail!("say what to write: --generate SEED, --mirror [FILE] or --plan [FILE]"),
    };
    layout.validate()?;
    if a.plan.is_some() {
        let plan = crate::floor_plan::of_layout(&layout, 0.0, 0);
        std::fs::write(&a.out, plan.to_toml()).map_err(|e| anyhow::anyhow!("--out {}: {e}", a.out.display()))?;
        println!("wrote {} (the plan of {} stations)", a.out.display(), plan.len());
        return Ok(());
    }
    std::fs::write(&a.out, layout.to_toml()).map_err(|e| anyhow::anyhow!("--out {}: {e}", a.out.display()))?;
    println!(
        "wrote {} ({} × {} m, {} obstacles, close pairs {:?})",
        a.out.display(),
        layout.floor.size[0],
        layout.floor.size[1],
        layout.obstacles.len(),
        layout.close_pairs()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::LayoutArgs;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        layout: LayoutArgs,
    }

    #[test]
    fn mirror_takes_the_built_in_floor_or_a_file() {
        // world/README.md's own command: --mirror with no file, then --out.
        let built_in = Cli::try_parse_from(["layout", "--mirror", "--out", "m.toml"]).unwrap().layout;
        assert_eq!(built_in.mirror, Some(None));
        let file = Cli::try_parse_from(["layout", "--mirror", "f.toml", "--out", "m.toml"]).unwrap().layout;
        assert_eq!(file.mirror, Some(Some("f.toml".into())));
        assert!(Cli::try_parse_from(["layout", "--generate", "3", "--mirror", "--out", "m.toml"]).is_err());
    }

    #[test]
    fn a_floor_s_plan_is_written_as_the_agent_reads_it() {
        let dir = std::env::temp_dir().join(format!("spwi-layout-plan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("plan.toml");
        let args =
            Cli::try_parse_from(["layout", "--generate", "7", "--plan", "--out", out.to_str().unwrap()]).unwrap();
        super::main(args.layout).unwrap();
        let plan = spwi_core::floor::FloorPlan::parse(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let floor = spwi_world::generate::layout(7);
        for k in spwi_proto::Station::ALL {
            assert_eq!(plan.station(k).unwrap().position, floor.station(k).work_spot, "{k}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
