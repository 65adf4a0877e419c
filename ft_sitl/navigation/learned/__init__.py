"""The learned navigators: NavRL (the released policy, its dynamic-obstacle detector and
safety shield) and ours (``learned``), with the policy input and output both share with the
training environment (:mod:`.policy_io`)."""
