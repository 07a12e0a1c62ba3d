//! Placeholder: filled by the backchannel work (issue 3).
