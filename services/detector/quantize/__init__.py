"""Post-training INT8 quantization with each runtime's own tool."""
