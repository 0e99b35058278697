"""The language-model family of chapters 13 and 14: a next-token policy, its reward model, RLHF, GRPO and DPO."""
