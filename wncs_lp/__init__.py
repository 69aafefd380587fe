"""wncs_lp: exact scheduling of multi-process WNCS with edge computing as average-cost MDPs."""
