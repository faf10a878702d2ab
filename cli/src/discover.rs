//! `presrs` argument types: DiscoverArgs.

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct DiscoverArgs {
    /// A folder of stances the node kept as unknown (`presrs node --keep-unknown DIR`).
    pub dir: PathBuf,
    /// The model the node ran with: its known terrains are what a group is new against.
    #[arg(long)]
    pub model: PathBuf,
    /// Write each stance's group (groups.csv) and a contact sheet per group (group-N.png)
    /// into this directory. Default: the table on stdout only.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Add a group as a new terrain of this name: writes the model with it (--out-model) and
    /// its entry in the terrains file (--terrains) when the catalog does not have the name.
    #[arg(long, value_name = "NAME", requires = "out_model")]
    pub add: Option<String>,
    /// The group --add adds, as numbered in the table; N,M adds several as one terrain (one
    /// ground its stances split in two modes). Default: the one new-ground group.
    #[arg(long, value_name = "N[,M...]", requires = "add", value_delimiter = ',',
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub group: Vec<usize>,
    /// The lab's word instead of a group: which kept stances were the new ground, as step
    /// ranges (`12-40`, `0:12-40` for foot 0), a labels CSV (`start_s,end_s,terrain[,foot]`:
    /// its rows naming --add's terrain) or a file listing kept.csv's file names.
    #[arg(long, value_name = "SPEC", requires = "add", conflicts_with = "group")]
    pub stances: Option<String>,
    /// The controller's config: --add says which gait it will run on the new terrain, and adds
    /// `NAME = <its safe gait>` under [terrain_gaits] (the file is checked, and kept as it was
    /// if the line would not load). Without it, --add prints the line to add.
    #[arg(long, value_name = "FILE", requires = "add")]
    pub controller_config: Option<PathBuf>,
    /// Where --add writes the model with the new terrain (a new file; the node's own model
    /// is not touched until you move this one in place and send SIGHUP).
    #[arg(long, value_name = "FILE")]
    pub out_model: Option<PathBuf>,
    /// The terrains file the node runs with: the new terrain's entry is added to it (the file
    /// made if missing), and the node reads it again on SIGHUP.
    #[arg(long, value_name = "FILE")]
    pub terrains: Option<PathBuf>,
    /// One JSON object on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// A fixed separation for new ground instead of the known terrains' own (for measuring
    /// the default: scripts/discover_study.py).
    #[arg(long, hide = true)]
    pub min_separation: Option<f64>,
    /// Leave each linked group whole (for measuring the split: scripts/discover_study.py).
    #[arg(long, hide = true)]
    pub no_split: bool,
    /// A fixed separation for splitting a linked group instead of the known terrains' own.
    #[arg(long, hide = true)]
    pub split_at: Option<f64>,
    /// Neighbouring unknown steps link as any two others do (for measuring their link).
    #[arg(long, hide = true, conflicts_with = "patch_link")]
    pub no_patches: bool,
    /// The link factor of neighbouring unknown steps (for measuring it).
    #[arg(long, hide = true)]
    pub patch_link: Option<f64>,
}
