"""The pure core: mapping model, codec and (later) planner and discovery builders. No I/O."""
