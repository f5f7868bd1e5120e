//! `spwi-sim layout`: writes a floor to a TOML file — a generated one, or the built-in
//! or a given one mirrored — so it can be read, rendered, edited and passed to any
//! tool with `--layouts FILE`.

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
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// `spwi-sim layout`.
pub fn main(a: LayoutArgs) -> Result<()> {
    let layout = match (&a.generate, &a.mirror) {
        (Some(seed), _) => generate::layout(*seed),
        (None, Some(None)) => Layout::default_layout().mirrored(),
        (None, Some(Some(p))) => Layout::load(p)?.mirrored(),
        (None, None) => bail!("say what to write: --generate SEED or --mirror [FILE]"),
    };
    layout.validate()?;
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
}
