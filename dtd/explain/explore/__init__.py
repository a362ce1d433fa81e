"""``dtd explore``: a local web page to question a trained run's high level."""
