//! Still images of records on the command line: the `synth-still` generator front end and the
//! `still` decoder (a streaming read of the image file through the pure decoder in
//! [`crate::pipeline::still`], then DSP, WAV and report).

pub mod cli;
