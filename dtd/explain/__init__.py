"""Looking inside a trained run: rendered episodes with their goal and sub-goal markers, the high
level's value heatmaps, and the report that gathers them."""
