"""Trained agents taken elsewhere: ONNX models of their acting paths (``dtd export``)."""
