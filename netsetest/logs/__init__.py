"""A recorded drive as the world (docs/your-log.md): readers.py reads the mapped signals of a ROS 2 bag, an MDF4
file or a Parquet/CSV table; align.py puts them on the run's steps; drive.py is the drive step by step, what the
vehicle role publishes in place of a model's truth."""
