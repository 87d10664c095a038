"""PPO training: the collection rate and its parts."""
