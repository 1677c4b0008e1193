//! How the network gets its history BEV: the one setting training and serving must share. A
//! checkpoint records the mode it was trained and validated with (its `history` metadata, see
//! [`crate::checkpoint::history`]), and the server feeds it so.

use serde::{Deserialize, Serialize};

/// How a step's BEV attends to the past (`crate::policy` serves it, `crate::train::data`
/// builds the same inputs in training).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum History {
    /// Two links: the step's BEV attends to the BEV of the frame 0.5 s back, which attended to
    /// the first-frame BEV of the frame 1 s back, and nothing older (three BEV passes a step;
    /// checkpoints trained with `--history chain`).
    #[default]
    Chain,
    /// One link: the step's BEV attends to the first-frame BEV of the frame 0.5 s back, which
    /// attended to nothing (two BEV passes a step; checkpoints trained with
    /// `--history link`).
    Link,
    /// The BEV each step plans from is the history of the step 0.5 s later: a recursion of
    /// unbounded depth (one BEV pass a step). Checkpoints that name no mode were validated so.
    Recursive,
}

impl std::fmt::Display for History {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            History::Chain => "chain",
            History::Link => "link",
            History::Recursive => "recursive",
        })
    }
}

impl std::str::FromStr for History {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "chain" => Ok(History::Chain),
            "link" => Ok(History::Link),
            "recursive" => Ok(History::Recursive),
            other => Err(format!(
                "unknown history mode '{other}' (chain, link or recursive)"
            )),
        }
    }
}
