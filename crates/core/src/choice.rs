//! Closed sets of named options (`depth.fit = "robust"`). The names are the config file's (serde);
//! the command line offers the same set through this list, so the core needs no argument parser.

/// A config value that is one of a fixed set of options.
pub trait Choice: Copy + 'static {
    /// Every option, in the order the docs list them.
    const ALL: &'static [Self];
}
