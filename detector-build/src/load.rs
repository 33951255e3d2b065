//! Configurations as TOML text: parsed, then validated by compiling them.

use crate::config::{Config, ConfigError};

/// Why a configuration file could not be loaded.
#[derive(Debug)]
pub enum LoadError {
    /// The text is not valid TOML or does not have the configuration's shape (the message
    /// gives line and column).
    Syntax(toml::de::Error),
    /// It parsed, but the configuration is invalid.
    Invalid(ConfigError),
}

impl core::fmt::Display for LoadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            // The toml crate's own text spans several lines (a source excerpt); keep its
            // position line and its message, on one line.
            LoadError::Syntax(e) => {
                let text = e.to_string();
                let position = text.lines().next().unwrap_or("TOML parse error");
                write!(f, "{position}: {}", e.message().trim_end())
            }
            LoadError::Invalid(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for LoadError {}

impl Config {
    /// Parses a TOML configuration (the format of `configs/approach.toml`) and validates it
    /// by building a detector from it.
    pub fn from_toml(text: &str) -> Result<Config, LoadError> {
        let config: Config = toml::from_str(text).map_err(LoadError::Syntax)?;
        crate::compile::compile(&config).map_err(LoadError::Invalid)?;
        Ok(config)
    }

    /// The configuration as TOML text.
    pub fn to_toml(&self) -> std::string::String {
        // Serializing plain data with only string keys cannot fail.
        toml::to_string_pretty(self).unwrap_or_default()
    }
}
