"""Recording and pictures: fleet runs as rosbag2/MCAP bags, the bag read back, PNG and GIF pictures.

Rooms: `bag` (writing a run as a rosbag2 MCAP bag that Foxglove and RViz replay), `bag_view`
(drawing a bag from its own messages), `render` (the fleet's PNG and GIF).

Imports: `jaxfilters`, `sims.fleet` and this package.
"""
