"""What a plan and a run did, checked independently: the executed cut's judge (a log and the
plant's true state), the judge's entry for a plan or a log, a second derivation of the
dynamics, a multibody engine, and motion capture."""
