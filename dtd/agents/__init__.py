"""What learns: networks, input normalisers, the learners (DDPG, TD3, SAC, TQC) with their one
update, the episode replay, pure HER relabelling, exploration, typed records, the flat DDPG/HER
agent and the Dot-to-Dot agent with its segments. Knows nothing of files, runs or screens; of the
environments only their spec and reward."""
