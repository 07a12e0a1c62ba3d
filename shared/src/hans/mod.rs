//! Placeholder: filled by the codec work (issue 3).
