"""The nine room types: their names and what each holds (furniture, wall items, floor and wall kinds)."""

from __future__ import annotations



ROOM_NAMES = (
    "kitchen",
    "living room",
    "office",
    "bedroom",
    "dining room",
    "library",
    "laundry room",
    "workshop",
    "hallway",
)


# Per room: floor items as (item, where) with where in back / side / free / back_corner;
# wall items as (item, wall, centre height) with wall in back / side; preferred floor and wall kinds.
ROOM_SPECS = {
    0: dict(  # kitchen
        floor=[("counter", "back"), ("counter", "side"), ("fridge", "back_corner"), ("table", "free"), ("chair", "free"), ("plant", "side")],
        wall=[("upper_cabinets", "back", 1.75), ("window", "side", 1.5), ("clock", "back", 2.2)],
        floors=("tiles", "tiles", "checker", "wood", "flat"), walls=("tiles", "paint", "paint", "brick")),
    1: dict(  # living room
        floor=[("sofa", "side"), ("tv", "back"), ("coffee_table", "free"), ("rug", "free"), ("floor_lamp", "back_corner"), ("plant", "back"), ("armchair", "side")],
        wall=[("picture", "back", 1.6), ("picture", "side", 1.5), ("window", "side", 1.5), ("shelf", "back", 1.8)],
        floors=("wood", "wood", "carpet", "gradient"), walls=("paint", "stripes", "wainscot", "brick"), width=(2.0, 2.8)),
    2: dict(  # office
        floor=[("desk", "back"), ("office_chair", "free"), ("bookshelf", "back"), ("bookshelf", "side"), ("plant", "back_corner"), ("boxes", "side")],
        wall=[("whiteboard", "back", 1.5), ("clock", "side", 2.1), ("window", "side", 1.5)],
        floors=("carpet", "wood", "checker", "flat"), walls=("paint", "paint", "wainscot")),
    3: dict(  # bedroom
        floor=[("bed", "side"), ("nightstand", "back"), ("wardrobe", "back"), ("rug", "free"), ("plant", "back_corner"), ("chair", "side")],
        wall=[("picture", "back", 1.5), ("window", "side", 1.5), ("shelf", "back", 1.8)],
        floors=("wood", "carpet", "carpet", "gradient"), walls=("paint", "stripes", "wainscot")),
    4: dict(  # dining room
        floor=[("dining_set", "free"), ("sideboard", "back"), ("plant", "back_corner"), ("floor_lamp", "side"), ("rug", "free")],
        wall=[("picture", "back", 1.6), ("window", "side", 1.5), ("clock", "back", 2.1)],
        floors=("wood", "tiles", "checker"), walls=("paint", "stripes", "wainscot", "brick"), width=(2.4, 2.9)),
    5: dict(  # library
        floor=[("bookshelf", "back"), ("bookshelf", "back"), ("bookshelf", "side"), ("armchair", "free"), ("floor_lamp", "free"), ("rug", "free"), ("table", "side")],
        wall=[("picture", "back", 1.9), ("clock", "side", 2.0)],
        floors=("wood", "carpet", "checker"), walls=("wainscot", "paint", "stripes")),
    6: dict(  # laundry room
        floor=[("washer", "back"), ("washer", "back"), ("basket", "free"), ("basket", "side"), ("boxes", "back_corner"), ("bench", "side")],
        wall=[("shelf", "back", 1.5), ("upper_cabinets", "back", 1.8), ("window", "side", 1.6)],
        floors=("tiles", "tiles", "flat", "checker"), walls=("tiles", "paint")),
    7: dict(  # workshop / garage
        floor=[("workbench", "back"), ("workbench", "side"), ("boxes", "back_corner"), ("boxes", "free"), ("bookshelf", "side"), ("chair", "free")],
        wall=[("shelf", "back", 1.4), ("shelf", "back", 1.8), ("whiteboard", "side", 1.5), ("door", "side", 1.05)],
        floors=("flat", "flat", "checker", "gradient"), walls=("brick", "paint", "brick")),
    8: dict(  # hallway / entrance
        floor=[("coat_rack", "back_corner"), ("bench", "back"), ("bench", "side"), ("plant", "side"), ("rug", "free"), ("boxes", "side")],
        wall=[("picture", "back", 1.55), ("door", "side", 1.05), ("clock", "back", 2.1), ("picture", "side", 1.5)],
        floors=("tiles", "wood", "checker", "carpet"), walls=("paint", "stripes", "wainscot")),
}
